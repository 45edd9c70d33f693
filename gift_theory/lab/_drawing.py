"""Drawing a set of figures into PNG files, in this process alone or shared with one helper process.

A *drawing* is a figure not drawn yet: a picklable callable that returns a matplotlib Figure (a
``functools.partial`` of a figure function of :mod:`._figures` with its numbers). Drawing is
single-threaded Python (the layout, the tick labels' text, the rasteriser), so a second core helps
only through a second process. With ``processes=2`` a helper is started (``python -m
gift_theory.lab._draw_helper``: a fresh interpreter, so no caller's ``__main__`` is run again and
no thread of this process is forked); the two take the drawings one at a time, the costliest
first, until none is left (so that they end together). Each file is written atomically by whichever process
drew it, and the bytes are the same either way: Agg draws the same figure to the same pixels in
any process. A helper that cannot start, or fails a drawing, costs time only: the drawing is done
here, where an error in it is raised as it would be without a helper.
"""

from __future__ import annotations

import atexit
import collections
import os
import pickle
import subprocess
import sys
import threading
import time


def draw_to(drawing, path: str) -> str:
    """Draw ``drawing`` (a Figure, or a callable returning one) and write it to ``path``
    atomically: a constrained-layout figure as it is (its layout already fits every artist), any
    other with the tight box."""
    from .._io import save_figure

    fig = drawing() if callable(drawing) else drawing
    return save_figure(fig, path, bbox_inches=_bbox(fig))


def _bbox(fig):
    """``bbox_inches`` for ``fig``: None when a constrained layout already fits every artist inside
    the figure, else "tight" (which makes matplotlib measure every artist's extent once more
    before the real draw)."""
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    return None if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine) else "tight"


def draw_all(jobs: list, processes: int = 1, meanwhile=None) -> list[str]:
    """Draw ``jobs`` (``(drawing, path)`` pairs, the costliest first) and write each; the paths,
    in the order given. ``processes=2`` shares them with a helper process when there are at least
    two and every drawing pickles (a Figure already drawn does not); else all are drawn here.
    ``meanwhile``: a callable this process runs first, while the helper starts on the drawings
    (a computation that does not need them), then it draws what is left."""
    if processes < 2 or len(jobs) < 2 or not all(callable(d) for d, _ in jobs):
        if meanwhile is not None:
            meanwhile()
        return [draw_to(d, p) for d, p in jobs]
    try:
        payloads = [pickle.dumps((d, p), protocol=pickle.HIGHEST_PROTOCOL) for d, p in jobs]
    except Exception:  # a drawing that does not pickle (a lambda, an open figure): all drawn here
        return draw_all(jobs, 1, meanwhile)
    share = _Share(payloads)
    feeder = threading.Thread(target=share.feed_helper, daemon=True)
    feeder.start()
    longest = 0.0
    try:
        if meanwhile is not None:
            meanwhile()
        while (i := share.take()) is not None:
            t0 = time.perf_counter()
            draw_to(*jobs[i])
            longest = max(longest, time.perf_counter() - t0)
    except BaseException:  # the helper gets no more; the drawing it holds is finished, then raised
        share.clear()
        feeder.join(timeout=60.0 + 10.0 * longest)
        raise
    # the helper's last drawing: as long as any of ours, ten times over, else it is stopped
    feeder.join(timeout=60.0 + 10.0 * longest)
    if feeder.is_alive():
        share.stop()
        feeder.join()
    for i in share.undone:  # what the helper did not draw is drawn here (an error in it raised here)
        draw_to(*jobs[i])
    return [p for _, p in jobs]


class _Share:
    """The drawings left (indices into the payloads, the costliest first), taken by both
    processes; those the helper took but did not confirm are ``undone``."""

    def __init__(self, payloads: list):
        self.payloads = payloads
        self.left = collections.deque(range(len(payloads)))
        self.lock = threading.Lock()
        self.undone: list[int] = []
        self.helper: subprocess.Popen | None = None

    def take(self) -> int | None:
        with self.lock:
            return self.left.popleft() if self.left else None

    def feed_helper(self) -> None:
        """In a thread: take the helper :func:`start_helper` started (else start one) and hand it
        one drawing at a time until none is left; after a drawing it does not confirm it gets no
        more."""
        try:
            self.helper = _take_started() or _start_helper()
        except Exception:  # no helper (no interpreter to start, no process left): all drawn here
            return
        try:
            while (i := self.take()) is not None:
                try:
                    self.helper.stdin.write(len(self.payloads[i]).to_bytes(8, "little") + self.payloads[i])
                    self.helper.stdin.flush()
                    ok = self.helper.stdout.read(1) == b"1"
                except Exception:  # a helper gone (a broken pipe, a closed file): this one is drawn here
                    ok = False
                if not ok:
                    self.undone.append(i)
                    break
        finally:
            _stop_helper(self.helper)

    def clear(self) -> None:
        with self.lock:
            self.left.clear()

    def stop(self) -> None:
        """Kill a helper that does not answer (its drawing is then ``undone``)."""
        if self.helper is not None:
            self.helper.kill()


_started: list = []  # a helper started ahead of its drawings (at most one), until draw_all takes it


def start_helper() -> None:
    """Start the helper process now, so that it is ready (its imports done, on a core this
    process leaves idle) when :func:`draw_all` is given ``processes=2``; the command line calls
    it before its computation when it will draw figures. Ended at exit if never used."""
    if not _started:
        try:
            _started.append(_start_helper())
        except Exception:  # draw_all tries again, and draws here without one
            return
        atexit.register(_stop_unused)


def _take_started() -> subprocess.Popen | None:
    while _started:
        helper = _started.pop()
        if helper.poll() is None:
            return helper
    return None


def _stop_unused() -> None:
    while _started:  # it has drawn nothing, so nothing is lost: not waited for
        _stop_helper(_started.pop(), kill=True)


def _start_helper() -> subprocess.Popen:
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")  # drawing does no linear algebra worth a thread pool
    return subprocess.Popen([sys.executable, "-m", "gift_theory.lab._draw_helper"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)


def _stop_helper(helper: subprocess.Popen, kill: bool = False) -> None:
    """End ``helper``: at the end of its input it exits (``kill``: at once, for one that has drawn
    nothing or does not answer); its pipes closed."""
    try:
        if kill:
            helper.kill()
        helper.stdin.close()
        helper.wait(timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        helper.kill()
        helper.wait()
    finally:
        helper.stdout.close()
