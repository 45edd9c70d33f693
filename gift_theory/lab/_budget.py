"""Memory within a small multiple of the file (issue 45): what a diagnosis holds per thread.

A candidate's fit and held-out score hold its model shots (4 r per input of every measured layer,
float32), the channels' pair distances in chunks of inputs (:data:`~._channels.CHUNK_BYTES`) and
the moment fit's draws: measured on a 50 MB file (16-32-16-8 with taps, 1740 inputs x 64 shots),
some 20 times the file's float32 shots per thread. The candidates run in up to 4 threads; for a
large file fewer, so that all of them together stay within :data:`LAB_MEMORY` (the numbers do not
depend on the thread count). A candidate with fitted offsets makes its refit null's replicates in
threads of its own (:func:`replicate_threads`): they come out of the same budget (on that file
two candidates with two replicate threads each raised the peak by 1.1 GB within seconds).
"""

from __future__ import annotations

#: bytes the threads of a diagnosis (candidates, and the replicates inside them) may hold together
LAB_MEMORY = 2 << 30
#: a candidate thread's working memory over the file's float32 shots (measured, see above)
PER_THREAD = 20


def shot_bytes(meas) -> int:
    """Bytes of the measured shots (every measured layer) in float32."""
    return 4 * meas.n * meas.r * sum(a.shape[2] for a in meas.layers())


def candidate_threads(meas) -> int:
    """How many candidate threads fit in :data:`LAB_MEMORY` for ``meas`` (at least 1)."""
    return int(max(1, LAB_MEMORY // max(PER_THREAD * shot_bytes(meas), 1)))


def replicate_threads(meas, candidates: int) -> int:
    """Threads for the replicates of one candidate when ``candidates`` candidate threads run at
    once: what :func:`candidate_threads` allows, shared among them (at least 1, at most
    ``candidates``)."""
    return int(max(1, min(candidates, candidate_threads(meas) // max(candidates, 1))))
