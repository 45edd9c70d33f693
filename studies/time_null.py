"""Null calibration of the identification's tests in acquisition time and of memory (issue 48).

    python -m studies.time_null OUT.jsonl --files 300 [--no-taps] [--first 0]

Per file a null chip (awgn only) from :mod:`studies.time_physics` (a random 2-4 layer network
as :func:`studies.blind._draw_setting` draws it, widths 3-28, 120 or 240 inputs x 32 or 64 shots,
s in [0.03, 0.15]) with acquisition times in one of three orders (random, blocked,
interleaved: a third each, by the file's index), the identification alone (:func:`identify`);
one JSON line per file: every row of the new tests (``wander``, ``map_drift``, ``lag``) with its
layer and raw p, the smallest Holm-adjusted p over all the identification's rows and the
classes named at 0.01. Resumable: files already in OUT are skipped. ``--summary`` prints the
rates (each test at 0.01 per layer, with the binomial 95 % interval; a class named per file).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

NEW_TESTS = ("wander", "map_drift", "lag")


def one(i: int, taps: bool, seed: int) -> dict:
    from gift_theory.lab import Measurement, identify
    from gift_theory._params import Layer

    from .blind import _draw_setting
    from .time_physics import ORDERS, simulate_time

    rng = np.random.default_rng([seed, 48, i])
    widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps)
    order = ORDERS[i % 3]
    y, tp, t, _ = simulate_time(rng, widths, Ws, bs, x, r, s, None, {"order": order})
    meas = Measurement(x, y, tuple(Layer(W, b) for W, b in zip(Ws, bs)), tuple(tp) if taps else None, t, "tanh")
    t0 = time.time()
    ident = identify(meas)
    rows = ident.rows()
    new = [{"test": r_["test"], "layer": int(r_["layer"]), "p": r_["p"], "p_adj": r_["p_adj"]}
           for r_ in rows if r_["test"] in NEW_TESTS]
    named = sorted({r_["class"] for r_ in rows if r_["p_adj"] < 0.01})
    return {"file": i, "taps": taps, "order": order, "arch": widths, "n": n, "r": r, "s": s,
            "min_p_adj": min(r_["p_adj"] for r_ in rows), "named": named, "new": new,
            "seconds": time.time() - t0}


def summary(path: str) -> dict:
    from scipy import stats

    with open(path) as f:
        rows = [json.loads(line) for line in f if line.strip()]
    out = {"files": len(rows)}
    for test in NEW_TESTS:
        ps = [x["p"] for r in rows for x in r["new"] if x["test"] == test]
        k = int(sum(p < 0.01 for p in ps))
        lo, hi = stats.binom.interval(0.95, len(ps), 0.01) if ps else (0, 0)
        out[test] = {"layers": len(ps), "below_0.01": k, "rate": k / max(len(ps), 1),
                     "binomial_95_at_1pct": [int(lo), int(hi)],
                     "ks_uniform_p": float(stats.kstest(ps, "uniform").pvalue) if len(ps) > 5 else None,
                     "by_order": {o: [int(sum(x["p"] < 0.01 for r in rows if r["order"] == o for x in r["new"]
                                              if x["test"] == test)),
                                      sum(1 for r in rows if r["order"] == o for x in r["new"] if x["test"] == test)]
                                  for o in ("random", "blocked", "interleaved")}}
    named = [r for r in rows if r["named"]]
    out["files_naming_a_class_at_holm_0.01"] = len(named)
    out["files_naming_memory_or_time_drift"] = sum(1 for r in named if {"memory", "time_drift"} & set(r["named"]))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.time_null", description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--files", type=int, default=300)
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--seed", type=int, default=4800)
    p.add_argument("--taps", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--summary", action="store_true")
    a = p.parse_args(argv)
    if a.summary:
        print(json.dumps(summary(a.out), indent=1))
        return 0
    done = set()
    if os.path.exists(a.out):
        with open(a.out) as f:
            done = {json.loads(line)["file"] for line in f if line.strip()}
    for i in range(a.first, a.first + a.files):
        if i in done:
            continue
        row = one(i, a.taps, a.seed)
        with open(a.out, "a") as f:
            f.write(json.dumps(row) + "\n")
        sys.stderr.write(f"[{i}] {row['order']} {row['arch']} min p_adj {row['min_p_adj']:.2g} named {row['named']} "
                         f"({row['seconds']:.0f} s)\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
