"""False alarms of the lab on correctly specified files at extreme noise levels (issue 45, point 5).

    python -m studies.levels_null run OUT.jsonl [--levels 1e-6,1e-3,1,10] [--sets 200] [--taps both|yes|no]
                                 [--minutes M] [--only-sets I,J,...]
    python -m studies.levels_null summary OUT.jsonl

``run`` simulates, per level s and taps setting, ``--sets`` null files (awgn at level s only: the
model is right) on the standing calibration's design -- a new 8-16-8-4 tanh network per set
(:func:`studies.calibrate._network`), 120 inputs uniform in [0, 1]^8, 32 shots -- and runs on
each what ``gift diagnose`` runs before it ranks candidates:

* the baseline: awgn's s fitted on half the inputs, the held-out test (``baseline_p``; below
  0.01 is ``missing_effect_detected``, a false alarm here);
* the layer-wise identification (``ident_min_p_adj``: the smallest Holm-adjusted p over every
  class and layer, and the classes named at 0.01: a false alarm);
* with taps, the one-step check per layer at its own level (``failing_layers``: Bonferroni 0.01
  over the layers; any is a false alarm) and each layer's level against the truth.

The run is resumable: rows already in OUT (same level, taps and set) are skipped, every row is
flushed as it is written, so a killed run continues where it stopped. Sets are taken in turn over
the levels and taps settings (set 0 at every level, then set 1, ...), so a run stopped by
``--minutes`` (no new set is started after M minutes) leaves the levels with equal counts. Each
row names the code's commit (``+dirty``: the tree's gift_theory or studies differ from it). ``summary`` prints per
level and taps the rates with their binomial 95 % intervals (Clopper-Pearson) and the binomial
test of each count against 1 % (of "any", the union of the three tests -- two without taps --
one-sided against its Bonferroni bound, 3 % or 2 %).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

WIDTHS, INPUTS, SHOTS = (8, 16, 8, 4), 120, 32


def _done(path):
    out = set()
    if os.path.exists(path):
        for line in open(path):
            try:
                row = json.loads(line)
            except ValueError:  # a line cut by a kill: written again
                continue
            if "set" in row:
                out.add((row["s"], row["taps"], row["set"]))
    return out


def one_set(s: float, taps: bool, i: int) -> dict:
    import jax

    import gift_theory as gt
    from gift_theory.lab import Session, identify, simulate_measurement
    from gift_theory.lab import failing_layers, one_step_check

    from .calibrate import _network

    t0 = time.time()
    arch, params = _network(1000 + i, WIDTHS)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(2000 + i), (INPUTS, WIDTHS[0])))
    meas = simulate_measurement(jax.random.PRNGKey(3000 + i), params, x, gt.Physics.create(s=s), shots=SHOTS,
                                taps=taps)
    session = Session.create(jax.random.PRNGKey(4000 + i), meas)
    c = session.baseline_comparison
    rows = identify(meas).rows()
    named = sorted({r["class"] for r in rows if r.get("p_adj", 1.0) < 0.01})
    out = {"s": s, "taps": taps, "set": i, "baseline_p": c.p_value, "fitted_s": float(session.baseline.physics.s),
           "ident_min_p_adj": min((r.get("p_adj", 1.0) for r in rows), default=1.0), "ident_named_0.01": named}
    if taps:
        where = one_step_check(session.k_step, session.baseline, meas)
        out["failing_layers"] = failing_layers(where)
        out["one_step_p"] = [w["p_value"] for w in where]
        out["layer_s"] = [w["s"] for w in where]
    out["seconds"] = time.time() - t0
    return out


def _commit():
    import subprocess

    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    head = subprocess.run(["git", "-C", here, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", here, "status", "--porcelain", "--", "gift_theory", "studies/*.py"],
                           capture_output=True, text=True)
    return (head.stdout.strip() or "unknown") + ("+dirty" if dirty.stdout.strip() else "")


def run(path, levels, sets, taps_list, minutes=None, only=None):
    done = _done(path)
    commit = _commit()
    t0 = time.time()
    with open(path, "a") as fh:
        for i in (range(sets) if only is None else only):
            for taps in taps_list:
                for s in levels:
                    if (s, taps, i) in done:
                        continue
                    if minutes is not None and time.time() - t0 > 60 * minutes:
                        sys.stderr.write(f"stopped after {minutes} minutes, before set {i}\n")
                        return
                    row = one_set(s, taps, i)
                    fh.write(json.dumps({**row, "commit": commit}) + "\n")
                    fh.flush()
                    sys.stderr.write(f"s = {s:g} taps {taps}: set {i} ({row['seconds']:.0f} s, "
                                     f"{time.time() - t0:.0f} s in all)\n")


def _interval(k, n):
    from scipy import stats

    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def summary(path):
    from scipy import stats

    rows = [json.loads(line) for line in open(path) if line.strip()]
    rows = [r for r in rows if "set" in r]
    print("| s | taps | sets | baseline p < 0.01 | a class named (Holm 0.01) | a failing layer (one-step) | "
          "any | fitted s / s (median) |")
    print("|---|---|---|---|---|---|---|---|")
    out = []
    for taps in (True, False):
        for s in sorted({r["s"] for r in rows}):
            rs = [r for r in rows if r["s"] == s and r["taps"] == taps]
            if not rs:
                continue
            n = len(rs)
            counts = {"baseline": sum(r["baseline_p"] < 0.01 for r in rs),
                      "ident": sum(bool(r["ident_named_0.01"]) for r in rs),
                      "layers": sum(bool(r.get("failing_layers")) for r in rs) if taps else None}
            counts["any"] = sum(r["baseline_p"] < 0.01 or bool(r["ident_named_0.01"]) or bool(r.get("failing_layers"))
                                for r in rs)
            cells = []
            for k in ("baseline", "ident", "layers", "any"):
                v = counts[k]
                if v is None:
                    cells.append("-")
                    continue
                lo, hi = _interval(v, n)
                if k == "any":  # a union of 3 tests at 1 % (2 without taps): at most 3 % (2 %) by Bonferroni
                    bound = 0.03 if taps else 0.02
                    p = stats.binomtest(v, n, bound, alternative="greater").pvalue
                    cells.append(f"{v}/{n} [{100 * lo:.1f}, {100 * hi:.1f}] % (against {100 * bound:.0f} %: p {p:.2g})")
                    continue
                p = stats.binomtest(v, n, 0.01).pvalue
                cells.append(f"{v}/{n} [{100 * lo:.1f}, {100 * hi:.1f}] % (binomial p {p:.2g})")
            ratio = float(np.median([r["fitted_s"] / r["s"] for r in rs]))
            print(f"| {s:g} | {'yes' if taps else 'no'} | {n} | " + " | ".join(cells) + f" | {ratio:.4f} |")
            out.append({"s": s, "taps": taps, "sets": n, **counts, "fitted_s_ratio_median": ratio})
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.levels_null", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out")
    r.add_argument("--levels", default="1e-6,1e-3,1,10")
    r.add_argument("--sets", type=int, default=200)
    r.add_argument("--taps", choices=("both", "yes", "no"), default="both")
    r.add_argument("--minutes", type=float, default=None, help="start no new set after this many minutes")
    r.add_argument("--only-sets", default=None, help="these sets only (e.g. those an earlier code flagged)")
    sm = sub.add_parser("summary")
    sm.add_argument("out")
    a = p.parse_args(argv)
    if a.cmd == "summary":
        summary(a.out)
        return 0
    taps = {"both": [True, False], "yes": [True], "no": [False]}[a.taps]
    only = None if a.only_sets is None else [int(v) for v in a.only_sets.split(",")]
    run(a.out, [float(v) for v in a.levels.split(",")], a.sets, taps, a.minutes, only)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
