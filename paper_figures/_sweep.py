"""A resumable sweep engine: a grid of independent jobs -> labelled arrays (xarray, netCDF).

A :class:`Sweep` names a grid (ordered dimensions, e.g. ``seed``, ``s0``, ``st``, ``net``) and
a job, a module-level function ``job(**point, **fixed) -> dict`` that returns numbers. Every
finished point is written at once as one small JSON file (temp name in the same folder, then
``os.replace``), so a sweep killed at any moment and started again continues where it
stopped: no finished point lost, none half-written. :func:`assemble` turns the point files
into an :class:`xarray.Dataset` (missing points are NaN) and :func:`run_sweep` saves it to
``<folder>/<name>.nc`` (h5netcdf, written atomically as well).

Jobs run through Dask: a ``dask.distributed.LocalCluster`` of worker processes by default,
any scheduler address to spread the same sweep over a cluster, or ``"synchronous"`` (in this
process; for debugging and tests). Point files are written by this (the client) process as
results arrive, so workers need no shared file system. Progress goes to stderr.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import json
import os
import socket
import sys
import time
from typing import Callable, Mapping

import numpy as np

from gift_theory import atomic_path, atomic_write_bytes

__all__ = ["Sweep", "run_sweep", "assemble", "load_points", "point_id", "restrict", "atomic_write_bytes", "toy_job"]


def _canon(v):
    """JSON-stable form of a grid value (numpy scalars -> Python)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, (list, tuple)):
        return [_canon(u) for u in v]
    if isinstance(v, dict):
        return {str(k): _canon(u) for k, u in sorted(v.items())}
    return v


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A grid of independent jobs.

    Parameters
    ----------
    name : str
        Names the sweep's folder and netCDF file.
    dims : mapping dim -> sequence of values
        The grid, in this dimension order (numbers or strings).
    job : str
        ``"module:function"`` of a module-level job; called as ``job(**point, **fixed)`` and
        returning a dict whose numeric (or boolean) values become data variables.
    fixed : mapping
        Options passed to every job; part of every point's identity, so changing them starts
        a fresh set of points instead of mixing results.
    """

    name: str
    dims: Mapping[str, tuple]
    job: str
    fixed: Mapping = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "dims", {str(k): tuple(_canon(list(v))) for k, v in self.dims.items()})
        object.__setattr__(self, "fixed", _canon(dict(self.fixed)))
        if ":" not in self.job:
            raise ValueError(f"sweep {self.name}: job must be 'module:function', got {self.job!r}")
        for k, v in self.dims.items():
            if len(v) == 0:
                raise ValueError(f"sweep {self.name}: dimension {k!r} has no values")
            if len(set(map(json.dumps, v))) != len(v):
                raise ValueError(f"sweep {self.name}: dimension {k!r} repeats a value")

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.dims.values())

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def points(self) -> list[dict]:
        """Every grid point as a dict dim -> value, in C order of ``dims``."""
        names = list(self.dims)
        return [dict(zip(names, (self.dims[n][i] for n, i in zip(names, idx)))) for idx in np.ndindex(*self.shape)]

    def resolve(self) -> Callable:
        module, func = self.job.split(":")
        return getattr(importlib.import_module(module), func)


def point_id(sweep: Sweep, point: Mapping) -> str:
    """A stable file name for one point: a hash of the job, the fixed options and the point."""
    spec = {"job": sweep.job, "fixed": sweep.fixed, "point": _canon(dict(point))}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:20]




def restrict(sweep: Sweep, **values) -> Sweep | None:
    """The same sweep on a sub-grid: each named dimension keeps only the given values that it
    has (None when one keeps none). Point ids do not depend on the grid, so the sub-sweep's
    points are the full sweep's (a run in pieces: the key cells first, then the rest)."""
    dims = dict(sweep.dims)
    for k, vals in values.items():
        if k not in dims:
            continue
        keep = [v for v in dims[k] if any(_canon(v) == _canon(w) for w in vals)]
        if not keep:
            return None
        dims[k] = tuple(keep)
    return Sweep(sweep.name, dims, sweep.job, sweep.fixed)


def _points_dir(folder: str, sweep: Sweep) -> str:
    return os.path.join(folder, sweep.name, "points")


def load_points(folder: str, sweep: Sweep) -> dict[str, dict]:
    """Finished points of ``sweep`` in ``folder``: point id -> record (unreadable files skipped)."""
    pdir = _points_dir(folder, sweep)
    wanted = {point_id(sweep, p) for p in sweep.points()}
    out = {}
    if not os.path.isdir(pdir):
        return out
    for fname in os.listdir(pdir):
        pid, ext = os.path.splitext(fname)
        if ext != ".json" or pid not in wanted:
            continue
        try:
            with open(os.path.join(pdir, fname)) as f:
                out[pid] = json.load(f)
        except (OSError, ValueError):  # cannot happen with atomic writes; a foreign file is ignored
            continue
    return out


@functools.lru_cache(maxsize=None)
def _worker_commit() -> str:
    """HEAD of the checkout at this worker process's first job, or '': which code a sweep that
    outlives a commit ran for each point. Not marked: modules a job imports only later (the
    rivals' identify-retrain imports the lab when it first runs) and uncommitted edits -- keep
    the checkout a sweep runs from at a commit."""
    return _git_commit()


def _call(job: str, point: dict, fixed: dict) -> dict:
    """Run one job (on a worker) and time it."""
    from gift_theory import use_compilation_cache

    use_compilation_cache()  # workers share compiled programs through the disk cache
    module, func = job.split(":")
    commit = _worker_commit()
    fn = getattr(importlib.import_module(module), func)
    t0 = time.perf_counter()
    result = fn(**point, **fixed)
    return {"result": result, "seconds": time.perf_counter() - t0, "host": socket.gethostname(), "pid": os.getpid(),
            "code_commit": commit}


def _persist(folder: str, sweep: Sweep, point: dict, out: dict) -> None:
    record = {"sweep": sweep.name, "job": sweep.job, "point": point, "fixed": sweep.fixed, **out,
              "finished": time.time()}
    path = os.path.join(_points_dir(folder, sweep), point_id(sweep, point) + ".json")
    atomic_write_bytes(path, json.dumps(_canon(record), default=float).encode())


def _numeric(v) -> bool:
    return isinstance(v, (bool, int, float, np.number)) and not isinstance(v, str)


def assemble(folder: str, sweep: Sweep):
    """The finished points of ``sweep`` as an :class:`xarray.Dataset`.

    Every numeric result key becomes a data variable over ``sweep.dims`` (NaN where a point is
    missing), plus ``seconds`` (job wall time) and ``done`` (bool); a result key named ``seconds``
    or ``done`` itself is kept as ``result_seconds`` / ``result_done``. Attributes record the job,
    the fixed options (JSON) and how many points are done.
    """
    import xarray as xr

    records = load_points(folder, sweep)
    points = sweep.points()
    shape = sweep.shape
    keys: list[str] = []
    for rec in records.values():
        for k, v in rec["result"].items():
            if _numeric(v) and k not in keys and k not in sweep.dims:  # a dim name cannot be a variable too
                keys.append(k)
    # a result's own "seconds" (a method's time) is kept as result_seconds: "seconds" is the job's
    name = {k: f"result_{k}" if k in ("seconds", "done") else k for k in keys}
    data = {name[k]: np.full(shape, np.nan) for k in keys}
    data["seconds"] = np.full(shape, np.nan)
    done = np.zeros(shape, bool)
    for flat, p in enumerate(points):
        rec = records.get(point_id(sweep, p))
        if rec is None:
            continue
        idx = np.unravel_index(flat, shape)
        done[idx] = True
        data["seconds"][idx] = rec["seconds"]
        for k in keys:
            v = rec["result"].get(k)
            if _numeric(v):
                data[name[k]][idx] = float(v)
    dims = list(sweep.dims)
    ds = xr.Dataset({k: (dims, v) for k, v in data.items()}, coords={d: list(vals) for d, vals in sweep.dims.items()})
    ds["done"] = (dims, done)
    ds.attrs.update(sweep=sweep.name, job=sweep.job, fixed_json=json.dumps(sweep.fixed, sort_keys=True),
                    points_done=int(done.sum()), points_total=sweep.size)
    return ds


def netcdf_engine() -> str:
    """``h5netcdf`` (netCDF4) when h5py is importable, else scipy's netCDF3 writer."""
    try:
        import h5py  # noqa: F401  (h5netcdf >= 1.7 no longer pulls it in)
    except ImportError:
        return "scipy"
    return "h5netcdf"


def save_dataset(ds, path: str) -> None:
    """Save an xarray Dataset to netCDF atomically (temp file in the same folder, then rename)."""
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine=netcdf_engine())


def open_dataset(path: str):
    """Load a saved sweep (fully into memory, so the file is not held open)."""
    import xarray as xr

    with xr.open_dataset(path, engine=netcdf_engine()) as ds:
        return ds.load()


class _Progress:
    """One stderr line per finished point: counts, rate and a remaining-time estimate."""

    def __init__(self, name: str, total: int, already: int, enabled: bool):
        self.name, self.total, self.done, self.enabled = name, total, already, enabled
        self.t0, self.new = time.perf_counter(), 0

    def log(self, msg: str) -> None:
        if self.enabled:
            sys.stderr.write(f"[sweep {self.name}] {msg}\n")
            sys.stderr.flush()

    def tick(self, point: dict, seconds: float, ok: bool = True) -> None:
        self.done += ok
        self.new += 1
        elapsed = time.perf_counter() - self.t0
        left = self.total - self.done
        eta = elapsed / self.new * left if self.new else float("nan")
        what = " ".join(f"{k}={v}" for k, v in point.items())
        self.log(f"{self.done}/{self.total} {'done' if ok else 'FAILED'} ({what}) job {seconds:.1f}s, "
                 f"elapsed {elapsed:.0f}s, ~{eta:.0f}s left")


def _client(scheduler, n_workers: int):
    from dask.distributed import Client, LocalCluster

    if scheduler in (None, "local", "processes"):
        # one thread per worker process: JAX jobs are CPU-bound and the GIL would serialise threads;
        # the scheduler's HTTP server on a free port (its default 8787 clashes with any other cluster)
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0")
        return Client(cluster), cluster
    return Client(scheduler), None


def open_client(scheduler: str | None = None, n_workers: int = 2):
    """A Dask client for several sweeps: ``(client, close)``; call ``close()`` when done.

    None/"local": a new ``LocalCluster`` of ``n_workers`` single-threaded processes; otherwise
    the address of a running scheduler."""
    client, cluster = _client(scheduler, n_workers)

    def close():
        client.close()
        if cluster is not None:
            cluster.close()

    return client, close


def run_sweep(sweep: Sweep, folder: str, *, scheduler: str | None = None, n_workers: int = 2,
              progress: bool = True, save: bool = True, max_new: int | None = None, client=None):
    """Run the missing points of ``sweep``, persisting each as it finishes; return the Dataset.

    Parameters
    ----------
    sweep : Sweep
    folder : str
        Data folder; points go to ``folder/<name>/points/<id>.json``, the assembled arrays to
        ``folder/<name>.nc``.
    scheduler : None | "local" | "synchronous" | address
        None/"local": a ``LocalCluster`` of ``n_workers`` processes; "synchronous": run in this
        process; anything else: the address of a running Dask scheduler (``tcp://host:8786``).
    n_workers : int
        Worker processes of the local cluster.
    max_new : int, optional
        Stop after this many new points (a partial run; rerun to continue).
    client : dask.distributed.Client, optional
        Use this client (e.g. from :func:`open_client`, shared by several sweeps so that workers
        keep their compiled functions and cached weights); ``scheduler`` is then ignored.

    Returns
    -------
    xarray.Dataset (see :func:`assemble`); ``attrs["failed"]`` counts points whose job raised
    in this run (they stay missing and are retried by the next run).
    """
    records = load_points(folder, sweep)
    todo = [p for p in sweep.points() if point_id(sweep, p) not in records]
    if max_new is not None:
        todo = todo[:max_new]
    prog = _Progress(sweep.name, sweep.size, len(records), progress)
    where = ("in process" if scheduler == "synchronous" and client is None else
             "shared client" if client is not None else scheduler or f"local cluster, {n_workers} workers")
    prog.log(f"{len(records)}/{sweep.size} points already done, {len(todo)} to run ({where})")
    failed = 0
    if todo and scheduler == "synchronous" and client is None:
        for p in todo:
            try:
                out = _call(sweep.job, p, sweep.fixed)
            except Exception as exc:  # a failing point stays missing; the sweep goes on
                failed += 1
                prog.log(f"job failed at {p}: {type(exc).__name__}: {exc}")
                prog.tick(p, float("nan"), ok=False)
                continue
            _persist(folder, sweep, p, out)
            prog.tick(p, out["seconds"])
    elif todo:
        from dask.distributed import as_completed

        close = None
        if client is None:
            client, close = open_client(scheduler, n_workers)
        try:
            futures = {}
            for p in todo:
                fut = client.submit(_call, sweep.job, p, sweep.fixed, pure=False,
                                    key=f"{sweep.name}-{point_id(sweep, p)}")
                futures[fut.key] = (fut, p)
            for fut in as_completed([f for f, _ in futures.values()]):
                p = futures[fut.key][1]
                try:
                    out = fut.result()
                except Exception as exc:
                    failed += 1
                    prog.log(f"job failed at {p}: {type(exc).__name__}: {exc}")
                    prog.tick(p, float("nan"), ok=False)
                    continue
                _persist(folder, sweep, p, out)
                prog.tick(p, out["seconds"])
        finally:
            if close is not None:
                close()
    ds = assemble(folder, sweep)
    ds.attrs["failed"] = failed
    ds.attrs["code_commit"] = _git_commit()
    if save:
        save_dataset(ds, os.path.join(folder, f"{sweep.name}.nc"))
    return ds


def _git_commit() -> str:
    """The checkout's HEAD commit when the sweep was assembled (uncommitted changes not marked), or ''."""
    import subprocess

    here = os.path.dirname(os.path.abspath(__file__))
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""
    return head


def toy_job(a, b, seconds: float = 0.0, fail_on=None, fail_flag: str | None = None, **_):
    """A stand-in job for tests and demonstrations: ``a * b`` and ``a + b`` after a sleep.

    Raises at ``a == fail_on`` (only while the file ``fail_flag`` exists, if one is named).
    """
    time.sleep(seconds)
    if fail_on is not None and a == fail_on and (fail_flag is None or os.path.exists(fail_flag)):
        raise RuntimeError(f"toy failure at a={a}")
    return {"prod": a * b, "sum": a + b, "label": f"{a}-{b}", "pid": os.getpid()}
