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
worker busy).

Points with the same (net, method, s0, seed) share their in-silico work at s0 (the memo of
:mod:`gift_theory.memo`: direction, curvature, paired se, slope at s0), whatever the chip's
noise level and law. A point records the seconds it spent computing shared work it did not
find done (``seconds_shared``). So a point's steady seconds exclude them, and

    work += groups x shared seconds of a group,

with the groups the distinct (net, method, s0, seed) of the target's sweeps, and a group's
seconds the median ``seconds_shared`` of the measured points that computed it. The sharing
between different methods (gift and pathwise use one direction) is not credited, so in this
respect the estimate errs high, except for one case: a (net, method) whose points all found
their shared work done (the pathwise rival uses gift's direction, computed by the GIFT sweep
that ran before it) is charged nothing, which holds when the target scale runs its sweeps in
the same order; the estimate lists these. The measured run must start with an empty memo
folder. ``--trainings-from DIR``: the training seconds from another run (one that trained
its nets; a run on cached weights measures none). The estimator sweep is counted with its measured median too. The numbers are
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
    per (net, method): seconds of the shared in-silico work of one group; compile seconds of a
    worker's first point; from the point files of ``scale`` in ``data_dir``."""
    sws = sweeps(scale)
    out = {"points": {}, "training": {}, "shared": {}, "compile_first_point": [], "counts": {}}
    setting, shared = {}, {}
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
            method = r["point"].get("method", sw.fixed.get("method"))
            key = (net, r["point"]["s0"], r["point"]["seed"])
            setting.setdefault(net, []).append((key, res.get("seconds_setting", np.nan)))
            sh = res.get("seconds_shared", 0.0)
            steady = r["seconds"] - res.get("seconds_setting", 0.0) - res.get("seconds_compiling", 0.0) - sh
            label = name if name != "rivals" else f"rivals:{method}"
            groups.setdefault(label, []).append(steady)
            out["compile_first_point"].append(res.get("seconds_compiling", np.nan))
            rows = shared.setdefault(f"{net}:{method}", {"computed": [], "hits": 0})
            if res.get("shared_misses", 0) > 0:
                rows["computed"].append(sh)
            rows["hits"] += int(res.get("shared_hits", 0))
        for label, v in groups.items():
            out["points"][label] = _median(v)
    for nm, rows in shared.items():
        # no miss: either nothing to share (0) or all of it done before this run (unmeasured)
        out["shared"][nm] = _median(rows["computed"]) if rows["computed"] else 0.0
        if not rows["computed"] and rows["hits"]:
            out.setdefault("shared_found_done", []).append(nm)
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


def estimate(data_dir: str, target: str = "paper", source: str = "paper-subset", workers: int = 2,
             trainings_from: str | None = None) -> dict:
    m = measured(data_dir, source)
    if trainings_from:
        m["training"] = measured(trainings_from, source)["training"]
    sc = get_scale(target)
    sws = sweeps(sc)
    rows, work, groups = [], 0.0, set()
    unestimated = []
    for name, sw in sws.items():
        if name != "estimators" and m["counts"].get(name, 0) == 0:
            # no point of it measured in the source (e.g. issue 25's sweeps): said so, not summed as NaN
            unestimated.append(name)
            rows.append({"sweep": name, "points": sw.size, "seconds": float("nan"), "estimated": False})
            continue
        if name != "estimators":
            for p in sw.points():
                groups.add((sw.fixed.get("net"), p.get("method", sw.fixed.get("method")), p["s0"], p["seed"]))
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
    per_group = {}
    for net, method, _, _ in groups:
        nm = f"{net}:{method}"
        per_group.setdefault(nm, [0, m["shared"].get(nm, float("nan"))])[0] += 1
    shared_s = sum(n * v for n, v in per_group.values())
    trainings = {net: len(sc.seeds) * len(set(sc.s0) | (set(sc.rival_s0) if net == "shallow" else set())
                                           | (set(sc.violated_s0) if net == "deep" else set()))
                 for net in sc.nets}
    train_s = sum(trainings[n] * m["training"].get(n, float("nan")) for n in trainings)
    compile_s = workers * m["compile_per_worker"]
    total = work + shared_s + train_s + compile_s
    return {"target": target, "source": source, "workers": workers, "sweeps": rows, "trainings": trainings,
            "training_seconds_per_net": m["training"], "training_seconds": train_s,
            "shared_groups": {nm: {"groups": n, "seconds_per_group": v} for nm, (n, v) in sorted(per_group.items())},
            "shared_seconds": shared_s, "shared_found_done": m.get("shared_found_done", []),
            "compile_seconds_per_worker": m["compile_per_worker"], "work_seconds": total,
            "wall_hours": total / workers / 3600, "measured_points": m["counts"], "not_estimated": unestimated}


def render(r: dict) -> str:
    lines = [f"{r['target']} scale estimated from {r['source']} job seconds, {r['workers']} workers:"]
    for s in r["sweeps"]:
        if s.get("estimated") is False:
            lines.append(f"  {s['sweep']:18s} {s['points']:5d} points  not estimated: no point of it measured")
            continue
        lines.append(f"  {s['sweep']:18s} {s['points']:5d} points  {s['seconds'] / 3600:7.2f} h of work")
        for meth, v in s.get("per_method_seconds_per_point", {}).items():
            lines.append(f"      {meth:18s} {v:7.1f} s per point")
    shared = [f"{nm} {g['groups']} x {g['seconds_per_group']:.1f} s" for nm, g in r["shared_groups"].items()
              if g["seconds_per_group"] != 0]
    lines.append(f"  shared in-silico work ({', '.join(shared) or 'none'}): {r['shared_seconds'] / 3600:.2f} h")
    if r["shared_found_done"]:
        lines.append(f"      found done by an earlier sweep or method, charged nothing: {', '.join(r['shared_found_done'])}")
    lines.append(f"  trainings {sum(r['trainings'].values())} ({', '.join(f'{k} {v:.0f} s' for k, v in r['training_seconds_per_net'].items())} each): "
                 f"{r['training_seconds'] / 3600:.2f} h")
    lines.append(f"  compiling: {r['compile_seconds_per_worker']:.0f} s per worker")
    lines.append(f"  total {r['work_seconds'] / 3600:.1f} h of work = {r['wall_hours']:.1f} h wall"
                 + (f" (without {', '.join(r['not_estimated'])})" if r.get("not_estimated") else ""))
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_figures.estimate", description=__doc__.splitlines()[0])
    p.add_argument("data_dir", nargs="?", default=None, help="data folder of the measured scale")
    p.add_argument("--scale", default="paper", help="the scale to estimate (default paper)")
    p.add_argument("--from-scale", default="paper-subset", help="the measured scale (default paper-subset)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--trainings-from", default=None, metavar="DIR",
                   help="take the training seconds from this data folder (a run that trained its nets)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    data = args.data_dir or os.path.join(HERE, "data", args.from_scale)
    for folder in (data, args.trainings_from):
        if folder is not None and not os.path.isdir(folder):
            sys.stderr.write(f"{folder}: no such folder\n")
            return 2
    if args.workers < 1:
        sys.stderr.write("--workers must be >= 1\n")
        return 2
    r = estimate(data, args.scale, args.from_scale, args.workers, args.trainings_from)
    sys.stdout.write((json.dumps(r, default=float) if args.json else render(r)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
