"""How long a scale's sweeps take, estimated from the job seconds another scale measured.

``python -m paper_figures.estimate [DATA_DIR] [--scale paper] [--from-scale paper-subset] [--workers 2]``

Every point file of a fine-tuning sweep records its wall seconds split by phase
(``seconds_setting``: loading w0, or training it when the point is the first of its (net, s0,
seed); ``seconds_compiling``: JAX compiling inside the job). From the measured scale this
module takes, per sweep and (for the rivals) per method, the median seconds of a point net of
training and compiling; the training seconds of a net (the first point's setting time less the
median loading time); and the compile seconds of a worker's first point. The target scale's
grid then gives

    work = sum_sweeps points x median point + trainings x training + workers x compile,

and the wall time is work / workers (the sweeps are independent points; the pool keeps every
worker busy). The estimator sweep is counted with its measured median too. The numbers are
this machine's, shared with whatever else ran while they were measured: the estimate says
which sweep and which method dominate and how the total scales, not a promise to the minute.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from ._scales import get_scale, sweeps
from ._sweep import load_points

HERE = os.path.dirname(os.path.abspath(__file__))
GIFT_SWEEPS = ("gift_awgn_deep", "gift_awgn_shallow", "gift_violated", "rivals")


def _median(v):
    v = np.asarray([x for x in v if x is not None and np.isfinite(x)], float)
    return float(np.median(v)) if v.size else float("nan")


def measured(data_dir: str, scale: str) -> dict:
    """Per sweep (and rival method): median steady seconds of a point; per net: training seconds;
    compile seconds of a worker's first point; from the point files of ``scale`` in ``data_dir``."""
    sws = sweeps(scale)
    out = {"points": {}, "training": {}, "compile_first_point": [], "counts": {}}
    setting = {}
    for name, sw in sws.items():
        recs = list(load_points(data_dir, sw).values())
        out["counts"][name] = len(recs)
        if not recs:
            continue
        if name == "estimators":
            out["points"][name] = _median(r["seconds"] for r in recs)
            continue
        groups = {}
        for r in recs:
            res = r["result"]
            net = sw.fixed.get("net")
            key = (net, r["point"]["s0"], r["point"]["seed"])
            setting.setdefault(net, []).append((key, res.get("seconds_setting", np.nan)))
            steady = r["seconds"] - res.get("seconds_setting", 0.0) - res.get("seconds_compiling", 0.0)
            label = name if name != "rivals" else f"rivals:{r['point']['method']}"
            groups.setdefault(label, []).append(steady)
            out["compile_first_point"].append(res.get("seconds_compiling", np.nan))
        for label, v in groups.items():
            out["points"][label] = _median(v)
    for net, rows in setting.items():
        load = _median(s for _, s in rows)
        first = {}
        for key, s in rows:
            first[key] = max(first.get(key, 0.0), s)
        out["training"][net] = _median(s - load for s in first.values())
    comp = [c for c in out["compile_first_point"] if np.isfinite(c)]
    out["compile_per_worker"] = float(sum(sorted(comp)[-6:])) if comp else float("nan")  # the few first points
    del out["compile_first_point"]
    return out


def estimate(data_dir: str, target: str = "paper", source: str = "paper-subset", workers: int = 2) -> dict:
    m = measured(data_dir, source)
    sc = get_scale(target)
    sws = sweeps(sc)
    rows, work = [], 0.0
    for name, sw in sws.items():
        if name == "rivals":
            per = {meth: m["points"].get(f"rivals:{meth}", float("nan")) for meth in sc.rival_methods}
            n_each = sw.size // len(sc.rival_methods)
            secs = sum(n_each * v for v in per.values())
            rows.append({"sweep": name, "points": sw.size, "seconds": secs,
                         "per_method_seconds_per_point": per})
        else:
            v = m["points"].get(name, float("nan"))
            secs = sw.size * v
            rows.append({"sweep": name, "points": sw.size, "seconds_per_point": v, "seconds": secs})
        work += secs
    trainings = {net: len(sc.seeds) * len(set(sc.s0) | (set(sc.rival_s0) if net == "shallow" else set())
                                           | (set(sc.violated_s0) if net == "deep" else set()))
                 for net in sc.nets}
    train_s = sum(trainings[n] * m["training"].get(n, float("nan")) for n in trainings)
    compile_s = workers * m["compile_per_worker"]
    total = work + train_s + compile_s
    return {"target": target, "source": source, "workers": workers, "sweeps": rows, "trainings": trainings,
            "training_seconds_per_net": m["training"], "training_seconds": train_s,
            "compile_seconds_per_worker": m["compile_per_worker"], "work_seconds": total,
            "wall_hours": total / workers / 3600, "measured_points": m["counts"]}


def render(r: dict) -> str:
    lines = [f"{r['target']} scale estimated from {r['source']} job seconds, {r['workers']} workers:"]
    for s in r["sweeps"]:
        lines.append(f"  {s['sweep']:18s} {s['points']:5d} points  {s['seconds'] / 3600:7.2f} h of work")
        for meth, v in s.get("per_method_seconds_per_point", {}).items():
            lines.append(f"      {meth:18s} {v:7.1f} s per point")
    lines.append(f"  trainings {sum(r['trainings'].values())} ({', '.join(f'{k} {v:.0f} s' for k, v in r['training_seconds_per_net'].items())} each): "
                 f"{r['training_seconds'] / 3600:.2f} h")
    lines.append(f"  compiling: {r['compile_seconds_per_worker']:.0f} s per worker")
    lines.append(f"  total {r['work_seconds'] / 3600:.1f} h of work = {r['wall_hours']:.1f} h wall")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_figures.estimate", description=__doc__.splitlines()[0])
    p.add_argument("data_dir", nargs="?", default=None, help="data folder of the measured scale")
    p.add_argument("--scale", default="paper", help="the scale to estimate (default paper)")
    p.add_argument("--from-scale", default="paper-subset", help="the measured scale (default paper-subset)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    data = args.data_dir or os.path.join(HERE, "data", args.from_scale)
    if not os.path.isdir(data) or args.workers < 1:
        sys.stderr.write(f"{data}: no such folder\n" if not os.path.isdir(data) else "--workers must be >= 1\n")
        return 2
    r = estimate(data, args.scale, args.from_scale, args.workers)
    sys.stdout.write((json.dumps(r, default=float) if args.json else render(r)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
