"""The calibration study: every fine-tuning method against chips with fixed per-device errors.

    python -m studies.calibration [--chips mesh,stuck,...] [--methods calibrate,pat,...] [--seeds 0,1,2]
        [--out studies/results/calibration.jsonl]

Each (chip, seed, method) row: the chip's w0 accuracy, the returned weights' accuracy, both scored
by the study's own referee (:func:`studies.faulty_chips.referee_accuracy`: the test set, 32 fresh
shots, argmax per shot, nothing charged), the ideal chip's accuracy of w0, the share of the lost
accuracy won back ((after - before) / (ideal - before)) and the chip evaluations used. Rows are
appended to a JSON-lines file as they land; a rerun skips the rows already there (resumable).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from .faulty_chips import CHIPS, FaultyChip, Faults, referee_accuracy

METHODS = ("none", "calibrate", "identify-retrain", "pat", "gift")


def run_one(ds, arch, w0, chip_name: str, seed: int, method: str, *, s: float = 0.05, budget: float = 20,
            taps: bool = True) -> dict:
    from gift_theory.finetune import RUNNERS, make_problem

    faults = CHIPS[chip_name]
    chip = FaultyChip(arch.widths, faults, s=s, seed=seed, taps=taps)
    w0n = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in w0]
    before = referee_accuracy(chip, w0n, ds.x_test, ds.labels_test)
    ideal = referee_accuracy(FaultyChip(arch.widths, Faults(), s=s, seed=seed), w0n, ds.x_test, ds.labels_test)
    problem = make_problem(arch, w0, ds.x_train, ds.y_train, s0=s, true_physics=None, budget=budget, seed=seed,
                           chip=chip)
    t0 = time.perf_counter()
    params, info = RUNNERS[method](problem)
    seconds = time.perf_counter() - t0
    after = referee_accuracy(chip, [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in params],
                             ds.x_test, ds.labels_test)
    lost = ideal[0] - before[0]
    return {"chip": chip_name, "taps": taps, "seed": seed, "method": method, "ideal": ideal[0],
            "before": before[0], "after": after[0], "after_se": after[1],
            "recovered": (after[0] - before[0]) / lost if lost > 0.005 else None,
            "evaluations": problem.evaluations_used(), "seconds": seconds,
            "accepted": info.get("accepted"), "reason": info.get("reason")}


ORDER = ("mesh", "stuck", "detector", "loss", "bias", "crosstalk", "dead", "mixed", "mesh_decomposed")
LABELS = {"mesh": "mesh errors on U and V", "stuck": "15 % of weights stuck at 0",
          "detector": "detector gains and offsets", "loss": "insertion loss per layer",
          "bias": "hidden bias offsets", "crosstalk": "thermal crosstalk", "dead": "3 dead neurons per hidden layer",
          "mixed": "all of them", "mesh_decomposed": "mesh decomposed afresh per W"}


#: methods that never ask the chip for taps: their rows with taps are their rows without (same chips, seeds)
TAPLESS = ("pat", "gift", "pat-identified")


def load_rows(*paths):
    rows = []
    for p in paths:
        if os.path.exists(p):
            with open(p) as fh:
                rows += [json.loads(line) for line in fh if line.strip()]
    have = {(r["chip"], r["taps"], r["seed"], r["method"]) for r in rows}
    rows += [dict(r, taps=False) for r in rows if r["taps"] and r["method"] in TAPLESS
             and (r["chip"], False, r["seed"], r["method"]) not in have]
    return rows


def summarize(rows, methods=("calibrate", "identify-retrain", "pat", "gift")):
    """Per (chip, taps): w0's accuracy, the ideal's, and per method the mean accuracy after, the mean
    share recovered, its minimum over seeds and the mean chip evaluations."""
    out = {}
    for r in rows:
        out.setdefault((r["chip"], r["taps"]), []).append(r)
    table = []
    for (chip, taps), rs in sorted(out.items(), key=lambda kv: (not kv[0][1], ORDER.index(kv[0][0]) if kv[0][0] in ORDER else 99)):
        row = {"chip": chip, "taps": taps, "before": float(np.mean([r["before"] for r in rs if r["method"] == "none"] or [np.nan])),
               "ideal": float(np.mean([r["ideal"] for r in rs])), "seeds": len({r["seed"] for r in rs}), "methods": {}}
        for m in methods:
            mr = [r for r in rs if r["method"] == m]
            if mr:
                rec = [(r["after"] - r["before"]) / (r["ideal"] - r["before"]) for r in mr
                       if r["ideal"] - r["before"] > 0.005]
                row["methods"][m] = {"after": float(np.mean([r["after"] for r in mr])),
                                     "recovered": float(np.mean(rec)) if rec else None,
                                     "recovered_min": float(np.min(rec)) if rec else None,
                                     "worse_than_w0": int(sum(r["after"] < r["before"] - 2 * r["after_se"] for r in mr)),
                                     "evaluations": float(np.mean([r["evaluations"] for r in mr])), "n": len(mr)}
        table.append(row)
    return table


def markdown(table, methods=("calibrate", "identify-retrain", "pat", "gift")) -> str:
    lines = ["| chip (w0's accuracy on it; ideal chip) | taps | " + " | ".join(f"`{m}`" for m in methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for row in table:
        cells = []
        for m in methods:
            c = row["methods"].get(m)
            if c is None:
                cells.append("-")
            elif c["recovered"] is None:  # the chip lost less than half a point: nothing to recover
                cells.append(f"{c['after']:.3f} (no loss; {c['evaluations']:.0f} ev)")
            else:
                worse = f"; {c['worse_than_w0']} below w0" if c["worse_than_w0"] else ""
                cells.append(f"{c['after']:.3f} ({c['recovered']:+.2f}; min {c['recovered_min']:+.2f}; "
                             f"{c['evaluations']:.0f} ev{worse})")
        lines.append(f"| {LABELS.get(row['chip'], row['chip'])} ({row['before']:.3f}; {row['ideal']:.3f}) | "
                     f"{'yes' if row['taps'] else 'no'} | " + " | ".join(cells) + " |")
    for taps in (True, False):
        sub = [r for r in table if r["taps"] == taps and r["chip"] != "mesh_decomposed"]
        if sub:
            means = []
            for m in methods:
                v = [r["methods"][m]["recovered"] for r in sub if m in r["methods"] and r["methods"][m]["recovered"] is not None]
                means.append(f"{np.mean(v):+.2f}" if v else "-")
            lines.append(f"| mean share recovered (but mesh decomposed afresh) | {'yes' if taps else 'no'} | "
                         + " | ".join(means) + " |")
    return "\n".join(lines)


def figure(table, path, methods=("calibrate", "identify-retrain", "pat", "gift")):
    import matplotlib

    matplotlib.use("agg")
    import matplotlib.pyplot as plt

    from gift_theory import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), sharey=True)
    for ax, taps in zip(axes, (True, False)):
        sub = [r for r in table if r["taps"] == taps]
        x = np.arange(len(sub))
        w = 0.8 / len(methods)
        for i, m in enumerate(methods):
            vals = [r["methods"].get(m, {}).get("recovered") for r in sub]
            lo = [r["methods"].get(m, {}).get("recovered_min") for r in sub]
            v = np.array([np.nan if a is None else a for a in vals])
            err = np.array([0 if (a is None or b is None) else a - b for a, b in zip(vals, lo)])
            ax.bar(x + (i - (len(methods) - 1) / 2) * w, v, w, yerr=[err, np.zeros_like(err)], capsize=2,
                   label=m, color=f"C{i}")
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.axhline(0.9, color="k", lw=0.5, ls=":")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xticks(x)
        ax.set_xticklabels([LABELS.get(r["chip"], r["chip"]) for r in sub], rotation=35, ha="right", fontsize=8)
        ax.set_title(f"{'with' if taps else 'without'} taps")
        ax.set_ylim(-1.0, 1.15)
    axes[0].set_ylabel("share of the lost accuracy recovered\n(after - w0) / (ideal chip - w0)")
    axes[0].legend(fontsize=8, loc="lower left")
    fig.suptitle("Calibrating chips with fixed per-device errors (digits 64-32-32-10, s0 = st = 0.05, 20 chip evaluations; "
                 "dashed: all recovered, dotted: 90 %)\nbars: mean over seeds, whisker down to the worst seed; "
                 "no bar: not run, or the chip lost no accuracy", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chips", default=",".join(CHIPS))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--no-taps", action="store_true", help="the chips cannot read their hidden layers")
    ap.add_argument("--out", default=None)
    ap.add_argument("--report", nargs="*", default=None, metavar="JSONL",
                    help="no runs: the table (markdown) and the figure of these result files")
    ap.add_argument("--figure", default="docs/figures/calibration.png")
    a = ap.parse_args(argv)
    if a.report is not None:
        table = summarize(load_rows(*a.report))
        print(markdown(table))
        print("figure:", figure(table, a.figure))
        return 0
    from gift_theory.finetune import load_setting

    ds, arch, w0 = load_setting("digits", "64-32-32-10", 0.05, 0, progress=False)
    import subprocess

    try:  # each row names the code it was measured with
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip() or None
    except OSError:
        commit = None
    done = set()
    if a.out and os.path.exists(a.out):
        with open(a.out) as fh:
            for line in fh:
                r = json.loads(line)
                done.add((r["chip"], r["taps"], r["seed"], r["method"]))
    for chip in a.chips.split(","):
        for seed in map(int, a.seeds.split(",")):
            for m in a.methods.split(","):
                if (chip, not a.no_taps, seed, m) in done:
                    continue
                row = run_one(ds, arch, w0, chip, seed, m, taps=not a.no_taps) | {"commit": commit}
                print(json.dumps(row), flush=True)
                if a.out:
                    with open(a.out, "a") as fh:
                        fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    sys.exit(main())
