"""The lab's memory budget: how many threads a diagnosis runs for the size of its file.

A candidate's fit holds the moment fit's draws and shots (2 r per input of every measured layer,
float32) and its offset fits' draws and tangents; its held-out score makes and reads its model
shots (4 r per input) a block of inputs at a time (:data:`~._shots.SHOT_BLOCK_BYTES`) and the
channels' pair distances in chunks of inputs (:data:`~._channels.CHUNK_BYTES`). Measured on a 50 MB
file (16-32-16-8 with taps, 1740 inputs x 64 shots, 25 MB of float32 shots), each candidate alone
in one thread after the session: bias_offset (fitted offsets, with its refit null) raised the
peak by 0.55 GB, weight_error by 0.52 GB, shot by 0.40 GB. :data:`PER_THREAD` counts 35 times the
file's float32 shots (0.87 GB there): what weight_error took when each layer's offset fit still
drew every noise site of the network, a margin for physics with more sites per layer.
The candidates run in up to 4 threads; for a large file fewer, so that all of them together stay
within :func:`lab_memory` (the numbers do not depend on the thread count). A candidate with fitted
offsets makes its refit null's replicates in threads of its own (:func:`replicate_threads`): they
come out of the same budget (on that file two candidates with two replicate threads each raised the
peak by 1.1 GB within seconds). The localisation (the baseline's residuals, one-step residuals and
signatures) reads the model's shots a block of inputs at a time (on that file its stages peaked
0.1-0.25 GB above the session) and is counted as one more thread: it runs beside the candidates
only when the budget has a thread left for it (:func:`localise_beside`), after them otherwise. The same threads
(:func:`default_workers`) run the other loops of independent, keyed work (:func:`map_in_threads`,
which the candidates and the refit null's replicates also run in): a tapped file's layers in the
identification, the next measurement's candidate designs, the test's power probes.
"""

from __future__ import annotations

import os
import re

from .._errors import GiftInputError

#: bytes the threads of a diagnosis (candidates, their replicates and the localisation) may hold
#: together, unless ``$GIFT_LAB_MEMORY`` says otherwise (:func:`lab_memory`)
LAB_MEMORY = 2 << 30
#: a candidate thread's working memory over the file's float32 shots (measured, see above)
PER_THREAD = 35

_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the system reports one, else the
    machine's count."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def lab_memory() -> int:
    """The budget in bytes: ``$GIFT_LAB_MEMORY`` (a whole number of bytes, or with a suffix K, M,
    G or T: binary units, e.g. ``512M``), else :data:`LAB_MEMORY`. A value that is not one of
    those is a bad input."""
    env = os.environ.get("GIFT_LAB_MEMORY", "").strip()
    if not env:
        return LAB_MEMORY
    m = re.fullmatch(r"(\d+)\s*([KMGT]?)(?:i?B)?", env, flags=re.I)
    if m is None or int(m.group(1)) == 0:
        raise GiftInputError(f"environment variable GIFT_LAB_MEMORY={env!r} is not a size: expected a positive "
                             "number of bytes such as 512M or 2G")
    return int(m.group(1)) * _UNITS[m.group(2).upper()]


def shot_bytes(meas) -> int:
    """Bytes of the measured shots (every measured layer) in float32."""
    return 4 * meas.n * meas.r * sum(a.shape[2] for a in meas.layers())


def candidate_threads(meas) -> int:
    """How many candidate threads fit in :func:`lab_memory` for ``meas`` (at least 1)."""
    return int(max(1, lab_memory() // max(PER_THREAD * shot_bytes(meas), 1)))


def replicate_threads(meas, candidates: int) -> int:
    """Threads for the replicates of one candidate when ``candidates`` candidate threads run at
    once: what :func:`candidate_threads` allows, shared among them (at least 1, at most
    ``candidates``)."""
    return int(max(1, min(candidates, candidate_threads(meas) // max(candidates, 1))))


def localise_beside(meas, candidates: int) -> bool:
    """Whether the localisation runs beside ``candidates`` candidate threads: only when the
    budget holds one thread more than they and their replicates may use at once."""
    return candidate_threads(meas) > candidates * replicate_threads(meas, candidates)


def default_workers(meas=None) -> int:
    """Threads for the candidates: the cores this process may use, at most 4 (``$GIFT_LAB_THREADS``),
    and -- given ``meas`` -- no more than :func:`candidate_threads` allows for its size (each
    thread holds a candidate's model shots and statistics; the numbers do not depend on it)."""
    env = os.environ.get("GIFT_LAB_THREADS", "").strip()
    if env.isdigit() and int(env) >= 1:
        return int(env)
    return max(1, min(4, usable_cores(), candidate_threads(meas) if meas is not None else 4))


def map_in_threads(f, items, threads: int) -> list:
    """``[f(item) for item in items]``, in up to ``threads`` threads (the lab's are
    :func:`default_workers`), in the order of ``items``. For work that is a function of its item
    alone (its own data, its own named subkey): the results are the same for any number of
    threads. Each call runs in a copy of the caller's context, so a phase clock still sees its
    compiles."""
    items = list(items)
    if min(len(items), int(threads)) <= 1:
        return [f(item) for item in items]
    import concurrent.futures
    import contextvars

    with concurrent.futures.ThreadPoolExecutor(max_workers=min(len(items), int(threads))) as pool:
        return list(pool.map(lambda item: contextvars.copy_context().run(f, item), items))


def one_blas_thread():
    """A context with one OpenBLAS/MKL thread: the lab's small dense algebra (the
    identification, and the threads that run identifications, entered once outside them so
    that their own limits restore one thread, not the process's count, whichever leaves
    first). Threads spinning on a loaded machine cost 100x there."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn brings it
        import contextlib
        return contextlib.nullcontext()
    return threadpool_limits(1)
