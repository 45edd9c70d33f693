"""Drawing a set of figures into PNG files, in this process alone or shared with one helper process.

A *drawing* is a figure not drawn yet: a picklable callable that returns a matplotlib Figure (a
``functools.partial`` of a figure function of :mod:`._figures` with its numbers). Drawing is
single-threaded Python (the layout, the tick labels' text, the rasteriser), so a second core helps
only through a second process. A :class:`Drawing` with ``processes=2`` hands each drawing, as
soon as it is given one, to a helper process (``python -m gift_theory.lab._draw_helper``: a fresh
interpreter, so no caller's ``__main__`` is run again and no thread of this process is forked),
while this process goes on computing the numbers of the next; at :meth:`Drawing.finish` both take
what is left one at a time, the costliest first, so that they end together. Each file is written
atomically by whichever process drew it, and the bytes are the same either way: Agg draws the
same figure to the same pixels in any process. A helper that cannot start, or fails a drawing,
costs time only: the drawing is done here, where an error in it is raised as it would be without
a helper.
"""

from __future__ import annotations

import atexit
import os
import pickle
import subprocess
import sys
import threading
import time


def draw_to(drawing, path: str) -> str:
    """Draw ``drawing`` (a Figure, or a callable returning one) and write it to ``path``
    atomically: a constrained-layout figure as it is (its layout already fits every artist), any
    other with the tight box. A ``.nc`` path takes a figure's numbers instead (an
    ``xarray.Dataset`` or a callable returning one: :func:`save_dataset`)."""
    from .._io import save_figure

    if is_numbers(path):
        return save_dataset(drawing() if callable(drawing) else drawing, path)
    fig = drawing() if callable(drawing) else drawing
    return save_figure(fig, path, bbox_inches=_bbox(fig))


def is_numbers(path: str) -> bool:
    """Whether ``path`` is a figure's numbers file (netCDF), not its picture."""
    return os.fspath(path).endswith(".nc")


def save_dataset(ds, path: str) -> str:
    """An ``xarray.Dataset`` written atomically as netCDF (h5netcdf)."""
    from .._io import atomic_path

    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf")
    return path


def _bbox(fig):
    """``bbox_inches`` for ``fig``: None when a constrained layout already fits every artist inside
    the figure, else "tight" (which makes matplotlib measure every artist's extent once more
    before the real draw)."""
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    return None if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine) else "tight"


class Drawing:
    """Figures drawn as they are handed over (:meth:`add`): with ``processes=2`` a helper process
    draws from the first one on, while this process goes on computing; :meth:`finish` then draws
    here what is left, sharing it with the helper, and waits for the helper's last. Use it as a
    context manager: leaving it on an error stops the helper after the drawing it holds. With
    ``processes=1``, and for a Figure drawn already or a drawing that does not pickle (a lambda),
    the drawing is done here, by :meth:`finish`."""

    def __init__(self, processes: int = 1):
        self.processes = processes
        self.jobs: list = []  # (drawing, path), in the order handed over
        self.here: list[int] = []  # those only this process can draw
        self.left: list = []  # (-cost, i) of those either process may take, not taken yet
        self.undone: list[int] = []  # taken by the helper, not drawn by it
        self.cond = threading.Condition()
        self.closed = False
        self.helper: subprocess.Popen | None = None
        self.feeder: threading.Thread | None = None
        self.longest = 0.0  # this process's longest drawing (the helper's time-out is ten of them)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is None:
            if not self.closed:
                self.finish()
            return False
        self._close(drop_left=True)  # an error: the helper gets no more; the drawing it holds is finished first
        if self.feeder is not None:
            self.feeder.join(timeout=60.0 + 10.0 * self.longest)
        return False

    def _close(self, drop_left: bool = False) -> None:
        """No more drawings are handed over (``drop_left``: and those not taken are dropped)."""
        with self.cond:
            if drop_left:
                self.left.clear()
            self.closed = True
            self.cond.notify_all()

    def add(self, jobs, costs=None) -> None:
        """Hand over ``(drawing, path)`` pairs; ``costs``: each one's relative drawing time (default
        1). The costliest left is drawn first, whenever it was handed over, so that the two
        processes end together."""
        costs = [1.0] * len(jobs) if costs is None else list(costs)
        with self.cond:
            for (drawing, path), cost in zip(jobs, costs):
                i = len(self.jobs)
                self.jobs.append((drawing, path))
                if self.processes >= 2 and callable(drawing):
                    self.left.append((-float(cost), i))
                else:
                    self.here.append(i)
            self.cond.notify_all()
        if self.left and self.feeder is None:
            self.feeder = threading.Thread(target=self._feed_helper, daemon=True)
            self.feeder.start()

    def finish(self, meanwhile=None) -> list[str]:
        """Run ``meanwhile`` (a computation that needs no figure) while the helper draws, then draw
        here what is left (with the helper; the numbers files, ``.nc``, are the helper's while it
        runs: this process need not import their writer), what only this process can draw, and
        what the helper did not; the paths, in the order handed over."""
        if meanwhile is not None:
            meanwhile()
        self._close()
        while (i := self._take(here=True)) is not None:
            self._draw_here(i)
        for i in self.here:
            self._draw_here(i)
        if self.feeder is not None:
            # the helper's last drawing: as long as any of ours, ten times over, else it is stopped
            self.feeder.join(timeout=60.0 + 10.0 * self.longest)
            if self.feeder.is_alive():
                if self.helper is not None:
                    self.helper.kill()
                self.feeder.join()
        for i in self.undone:  # what the helper did not draw is drawn here (an error in it raised here)
            self._draw_here(i)
        while (i := self._take()) is not None:  # what a helper that stopped left
            self._draw_here(i)
        return [p for _, p in self.jobs]

    def _draw_here(self, i: int) -> None:
        t0 = time.perf_counter()
        draw_to(*self.jobs[i])
        self.longest = max(self.longest, time.perf_counter() - t0)

    def _take(self, wait: bool = False, here: bool = False) -> int | None:
        """The costliest drawing left, the first handed over among equals (None when none is);
        ``wait``: until one is handed over or :meth:`finish` is called; ``here``: for this
        process, which leaves the numbers files (``.nc``) to a running helper -- and the helper
        takes them first, as they come, while this process still computes."""
        with self.cond:
            while wait and not self.left and not self.closed:
                self.cond.wait()
            numbers = [job for job in self.left if is_numbers(self.jobs[job[1]][1])]
            pool = self.left
            if here and self.feeder is not None and self.feeder.is_alive():
                pool = [job for job in self.left if job not in numbers]
            elif not here and numbers:  # the helper writes them first, while this process is busy elsewhere
                pool = numbers[:1]
            if not pool:
                return None
            best = min(pool)
            self.left.remove(best)
            return best[1]

    def _feed_helper(self) -> None:
        """In a thread: take the helper :func:`start_helper` started (else start one) and hand it
        one drawing at a time until none is left; after a drawing it does not confirm it gets no
        more."""
        try:
            self.helper = _take_started() or _start_helper()
        except Exception:  # no helper (no interpreter to start, no process left): all drawn here
            return
        try:
            while (i := self._take(wait=True)) is not None:
                try:  # pickled only now: one drawing's numbers copied at a time
                    payload = pickle.dumps(self.jobs[i], protocol=pickle.HIGHEST_PROTOCOL)
                except Exception:  # it does not pickle (a lambda): drawn here, the helper goes on
                    self.undone.append(i)
                    continue
                try:
                    self.helper.stdin.write(len(payload).to_bytes(8, "little") + payload)
                    self.helper.stdin.flush()
                    ok = self.helper.stdout.read(1) == b"1"
                except Exception:  # a helper gone (a broken pipe, a closed file): this one is drawn here
                    ok = False
                if not ok:
                    self.undone.append(i)
                    break
        finally:
            _stop_helper(self.helper)


_started: list = []  # a helper started ahead of its drawings (at most one), until a Drawing takes it


def start_helper() -> None:
    """Start the helper process now, so that it is ready (its imports done, on a core this
    process leaves idle) when a :class:`Drawing` with ``processes=2`` gets its first drawing; the
    command line calls it before its computation when it will draw figures. One never used is
    killed at exit, or -- after ``os._exit``, as the ``gift`` command leaves -- ends at the end of
    its input, once its imports are done."""
    if not _started:
        try:
            _started.append(_start_helper())
        except Exception:  # the Drawing tries again, and draws here without one
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
