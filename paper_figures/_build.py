"""Rebuild the figures: run the sweeps they need (resumable, through Dask), then draw from saved data.

``python -m paper_figures [--scale quick|paper] [--only NAME] [--scheduler ADDRESS]`` and
``gift figures`` both call :func:`build`. Data go to ``paper_figures/data/<scale>/`` (one
netCDF file per sweep, one JSON file per finished point), figures to
``paper_figures/figures/<scale>/<name>.png``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time

import numpy as np

from ._jobs import unavailable
from ._scales import SCALES, get_scale, sweeps
from gift_theory import save_figure

from ._sweep import _git_commit, assemble, load_points, open_client, open_dataset, restrict, run_sweep, save_dataset

HERE = os.path.dirname(os.path.abspath(__file__))

#: every figure script, in the paper's order, then ours
FIGURES = (
    "performance_gift",
    "performance_gift_shallow",
    "performance_gift_violated_noise_assumption",
    "performance_gift_test_data",
    "performance_gift_test_data_violated_awgn",
    "abs_performance_gift",
    "example_fine_tuning",
    "rivals",
    "estimator_convergence",
    "bound_region",
    "error_ladder",
    "predicted_vs_realised",
    "gain_vs_baseline",
    "ceiling",
    "undertrained",
    "extended",
)


def _save_png(fig, path: str) -> None:
    """Save atomically: a temp file in the same folder, then ``os.replace``."""
    save_figure(fig, path)


def _sweep_summary(name, ds) -> dict:
    sec = np.asarray(ds["seconds"].values, float)
    sec = sec[np.isfinite(sec)]
    return {"name": name, "points_done": int(ds.attrs.get("points_done", 0)),
            "points_total": int(ds.attrs.get("points_total", 0)), "failed": int(ds.attrs.get("failed", 0)),
            "seconds_per_point_mean": float(sec.mean()) if sec.size else None,
            "seconds_per_point_max": float(sec.max()) if sec.size else None,
            "seconds_jobs_total": float(sec.sum())}


def default_root() -> str:
    """Where the sweep data and figures go unless told: this folder in a source checkout (its
    ``data/`` and ``figures/`` are the repository's), else ``./gift_figures`` in the working
    directory -- never inside an installed package."""
    if os.path.isfile(os.path.join(os.path.dirname(HERE), "pyproject.toml")) and os.access(HERE, os.W_OK):
        return HERE
    return os.path.join(os.getcwd(), "gift_figures")


def build(scale: str = "quick", *, only: str | None = None, scheduler: str | None = None, n_workers: int = 2,
          mnist_folder: str | None = None, data_dir: str | None = None, figure_dir: str | None = None,
          compute: bool = True, progress: bool = True, options: dict | None = None, cells=None) -> dict:
    """Run the sweeps behind the chosen figures, then draw each figure from the saved data.

    Parameters
    ----------
    scale : "quick" | "paper" | "tiny"
    only : one figure name (see :data:`FIGURES`), default all
    scheduler : None (local process pool), "synchronous", or a Dask scheduler address
    n_workers : worker processes of the local pool
    mnist_folder : an MNIST IDX folder (paper scale on full MNIST instead of mnist5k)
    data_dir, figure_dir : default ``data/<scale>``, ``figures/<scale>`` under :func:`default_root`
        (``paper_figures/`` in a source checkout, else ``./gift_figures``)
    compute : False draws from existing data only
    options : extra keyword arguments for every fine-tuning job
    cells : a run in pieces: only the points at these (s0, st) cells, cell by cell in this
        order (``"key"``: the scale's ``key_cells``); their point files land as usual, then
        each sweep's netCDF is assembled from every point saved so far (NaN where missing;
        ``points_done`` says how many); no figure is drawn

    Returns
    -------
    dict with ``scale``, ``seconds`` (wall), ``sweeps`` (points done/total, seconds per point)
    and ``figures`` (name, label, path, status "drawn" or the reason it is not).
    """
    import matplotlib

    matplotlib.use("agg")  # a batch build draws to files only; the figure functions choose no backend
    t0 = time.perf_counter()
    sc = get_scale(scale)
    data_dir = data_dir or os.path.join(default_root(), "data", sc.name)
    figure_dir = figure_dir or os.path.join(default_root(), "figures", sc.name)
    names = FIGURES if only is None else (only,)
    mods = {n: importlib.import_module(f"paper_figures.{n}") for n in names}
    all_sweeps = sweeps(sc, mnist_folder=mnist_folder, options=options)
    needed = []
    for m in mods.values():
        # a figure's SWEEPS are computed; its OPTIONAL ones are drawn when saved (computed by other figures)
        needed += [s for s in m.SWEEPS if s not in needed and s in all_sweeps]
    if cells is not None:
        return _run_cells(sc, all_sweeps, needed, sc.key_cells if cells == "key" else cells, data_dir, scheduler,
                          n_workers, progress, t0)

    client, close = None, None
    if compute and scheduler != "synchronous":
        # one pool for all sweeps: workers keep their compiled functions and loaded weights
        pending = [s for s in needed if not unavailable(all_sweeps[s].job, all_sweeps[s].fixed)
                   and len(load_points(data_dir, all_sweeps[s])) < all_sweeps[s].size]
        if pending:
            client, close = open_client(scheduler, n_workers)
    try:
        return _build(sc, mods, all_sweeps, needed, data_dir, figure_dir, compute, progress, scheduler, n_workers,
                      client, t0)
    finally:
        if close is not None:
            close()


def _build(sc, mods, all_sweeps, needed, data_dir, figure_dir, compute, progress, scheduler, n_workers, client, t0):
    sweep_info, sweep_problem = [], {}
    loaded = {}  # sweep name -> Dataset, read once per build

    def data_of(sname):
        if sname not in loaded:
            loaded[sname] = open_dataset(os.path.join(data_dir, f"{sname}.nc"))
        return loaded[sname]

    for sname in needed:
        sw = all_sweeps[sname]
        path = os.path.join(data_dir, f"{sname}.nc")
        problem = unavailable(sw.job, sw.fixed) if compute else None
        if problem:
            sweep_problem[sname] = problem
            if progress:
                sys.stderr.write(f"[figures] sweep {sname} not run: {problem}\n")
            if not os.path.isfile(path):
                sweep_info.append({"name": sname, "error": problem})
                continue
        if compute and not problem:
            ds = loaded[sname] = run_sweep(sw, data_dir, scheduler=scheduler, n_workers=n_workers,
                                           progress=progress, client=client)
        elif os.path.isfile(path):
            ds = data_of(sname)
        else:
            sweep_problem[sname] = f"no saved data {path}; run without --draw-only"
            sweep_info.append({"name": sname, "error": sweep_problem[sname]})
            continue
        sweep_info.append(_sweep_summary(sname, ds))

    figures = []
    for name, mod in mods.items():
        entry = {"name": name, "label": mod.LABEL, "path": os.path.join(figure_dir, f"{name}.png")}
        absent = [s for s in mod.SWEEPS if s not in all_sweeps]
        if absent:  # the scale does not define this figure's sweeps (issue 25's are at paper and tiny only)
            entry["status"], entry["path"] = f"{NOT_AT_SCALE}: scale {sc.name} has no sweep {', '.join(absent)}", None
            if progress:
                sys.stderr.write(f"[figures] {name}: {entry['status']}\n")
            figures.append(entry)
            continue
        try:
            if compute and hasattr(mod, "compute"):
                mod.compute(sc, data_dir)
            missing = [s for s in mod.SWEEPS if not os.path.isfile(os.path.join(data_dir, f"{s}.nc"))]
            if missing:
                raise RuntimeError("; ".join(sweep_problem.get(s, f"no data for sweep {s}") for s in missing))
            data = {s: data_of(s) for s in mod.SWEEPS}
            # optional inputs: drawn when saved, left out (and said so in the figure) when not
            data.update({s: data_of(s) for s in getattr(mod, "OPTIONAL", ())
                         if os.path.isfile(os.path.join(data_dir, f"{s}.nc"))})
            if hasattr(mod, "load"):  # figures with their own saved data (closed forms)
                data.update(mod.load(data_dir))
            _save_png(mod.draw(data), entry["path"])
            entry["status"] = "drawn"
        except Exception as exc:  # one figure's failure must not stop the others
            entry["status"] = f"{type(exc).__name__}: {exc}"
            entry["path"] = None
        if progress:
            sys.stderr.write(f"[figures] {name}: {entry['status']}\n")
        figures.append(entry)

    result = {"scale": sc.name, "data_dir": data_dir, "figure_dir": figure_dir, "sweeps": sweep_info,
              "figures": figures, "seconds": time.perf_counter() - t0}
    try:
        from .claims import summarise

        result["claims"] = summarise(data_dir, loaded)
    except Exception as exc:  # claims need the GIFT sweeps; say why they are absent
        result["claims"] = {"error": f"{type(exc).__name__}: {exc}"}
    return result


def _run_cells(sc, all_sweeps, needed, cells, data_dir, scheduler, n_workers, progress, t0) -> dict:
    """Run the needed sweeps' points at the given (s0, st) cells, cell by cell (see :func:`build`)."""
    client, close = (None, None) if scheduler == "synchronous" else open_client(scheduler, n_workers)
    info, touched = [], set()
    try:
        for s0, st in cells:
            for sname in needed:
                sw = all_sweeps[sname]
                if "s0" not in sw.dims or "st" not in sw.dims or unavailable(sw.job, sw.fixed):
                    continue
                sub = restrict(sw, s0=(float(s0),), st=(float(st),))
                if sub is None:
                    continue
                ds = run_sweep(sub, data_dir, scheduler=scheduler, n_workers=n_workers, progress=progress,
                               client=client, save=False)
                info.append(dict(_sweep_summary(sname, ds), cell={"s0": float(s0), "st": float(st)}))
                touched.add(sname)
    finally:
        if close is not None:
            close()
        for sname in sorted(touched):  # what has landed, as the full grid's arrays (a partial sweep)
            ds = assemble(data_dir, all_sweeps[sname])
            ds.attrs["code_commit"] = _git_commit()
            save_dataset(ds, os.path.join(data_dir, f"{sname}.nc"))
    return {"scale": sc.name, "data_dir": data_dir, "figure_dir": None, "sweeps": info, "figures": [],
            "seconds": time.perf_counter() - t0, "cells": [[float(a), float(b)] for a, b in cells]}


def _parse_cells(text: str):
    """``key`` or ``S0:ST,S0:ST,...`` -> "key" or [(s0, st), ...]; bad input -> GiftInputError."""
    from gift_theory import GiftInputError

    if text == "key":
        return "key"
    out = []
    for part in text.split(","):
        try:
            a, b = part.split(":")
            out.append((float(a), float(b)))
        except ValueError:
            raise GiftInputError(f"--cells {text}: expected 'key' or S0:ST[,S0:ST...], got {part!r}") from None
    return out


def add_arguments(parser) -> None:
    parser.add_argument("--scale", default="quick", choices=tuple(SCALES),
                        help="quick (digits, small nets, 2 seeds: minutes) | paper (the paper's nets, mnist5k, "
                             "10 seeds: hours) | paper-subset (the paper's nets, 3 seeds, two pairs for the "
                             "violated laws and rivals) | tiny (tests)")
    parser.add_argument("--only", default=None, choices=FIGURES, metavar="NAME",
                        help=f"one figure: {', '.join(FIGURES)}")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="Dask scheduler address (tcp://host:8786) to spread the sweeps over a cluster; "
                             "'synchronous' runs in this process; default: a local pool of --workers processes")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    parser.add_argument("--data-folder", "--mnist-folder", dest="mnist_folder", default=None, metavar="DIR",
                        help="folder with the MNIST IDX files: fine-tune on full MNIST instead of mnist5k")
    parser.add_argument("--data-dir", default=None, metavar="DIR",
                        help="where the sweep data go (default: paper_figures/data/SCALE in a source checkout, "
                             "else ./gift_figures/data/SCALE)")
    parser.add_argument("--figure-dir", default=None, metavar="DIR",
                        help="where the PNGs go (default: paper_figures/figures/SCALE in a source checkout, else "
                             "./gift_figures/figures/SCALE)")
    parser.add_argument("--draw-only", action="store_true", help="draw from saved data, run no sweep")
    parser.add_argument("--cells", default=None, metavar="key|S0:ST,...",
                        help="a run in pieces: only the points at these (s0, st) cells, in this order ('key': the "
                             "scale's key cells); the netCDF holds every point saved so far; no figure drawn")


def check_arguments(args) -> None:
    """Bad input -> one-line GiftInputError (reference §4)."""
    from gift_theory import GiftInputError

    if args.workers < 1:
        raise GiftInputError(f"--workers {args.workers}: must be at least 1")
    if args.mnist_folder is not None and not os.path.isdir(args.mnist_folder):
        raise GiftInputError(f"--data-folder {args.mnist_folder}: no such folder")
    for flag, d in (("--data-dir", args.data_dir), ("--figure-dir", args.figure_dir)):
        if d is not None and os.path.exists(d) and not os.path.isdir(d):
            raise GiftInputError(f"{flag} {d}: exists and is not a folder")


def run_args(args) -> dict:
    check_arguments(args)
    cells = getattr(args, "cells", None)
    return build(args.scale, only=args.only, scheduler=args.scheduler, n_workers=args.workers,
                 mnist_folder=args.mnist_folder, data_dir=args.data_dir, figure_dir=args.figure_dir,
                 compute=not args.draw_only, cells=None if cells is None else _parse_cells(cells))


def render(result: dict) -> str:
    lines = [f"scale {result['scale']}: {result['seconds']:.0f} s wall"]
    if "cells" in result:
        lines.append(f"  cells {result['cells']} (a piece: netCDF of the points so far, no figure)")
    for s in result["sweeps"]:
        if "error" in s:
            lines.append(f"  sweep {s['name']}: {s['error']}")
        else:
            per = s["seconds_per_point_mean"]
            where = f" at s0={s['cell']['s0']:g}, st={s['cell']['st']:g}" if "cell" in s else ""
            lines.append(f"  sweep {s['name']}{where}: {s['points_done']}/{s['points_total']} points"
                         + (f", {per:.1f} s per point" if per is not None else ""))
    for f in result["figures"]:
        lines.append(f"  {f['label']}: {f['path'] if f['status'] == 'drawn' else f['status']}")
    claims = result.get("claims", {})
    if "error" not in claims:
        for k, v in claims.items():
            lines.append(f"  claim {k}: {v.get('summary', '')}")
    return "\n".join(lines)


#: a figure whose sweeps the scale does not define is skipped, not failed
NOT_AT_SCALE = "not at this scale"


def failed(result: dict) -> bool:
    return any(f["status"] != "drawn" and not f["status"].startswith(NOT_AT_SCALE) for f in result["figures"])


def main(argv=None, only: str | None = None) -> int:
    """``python -m paper_figures`` (or a figure script with ``only``): build, print a summary.

    ``python -m paper_figures --profile [--net deep|shallow] ...`` profiles one paper-scale net
    instead (:mod:`paper_figures._profile`)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if only is None and "--profile" in argv:
        from ._profile import main as profile_main

        return profile_main([a for a in argv if a != "--profile"])
    parser = argparse.ArgumentParser(prog="python -m paper_figures" + (f".{only}" if only else ""),
                                     description=__doc__.splitlines()[0])
    add_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    args = parser.parse_args(argv)
    if only is not None:
        args.only = only
    from gift_theory import GiftInputError

    try:
        result = run_args(args)
    except GiftInputError as exc:
        sys.stderr.write(f"{exc}\n")
        return 2
    sys.stdout.write((json.dumps(result, default=float) if args.json else render(result)) + "\n")
    return 1 if failed(result) else 0
