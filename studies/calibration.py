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
            "recovered": (after[0] - before[0]) / lost if lost > 0 else None,
            "evaluations": problem.evaluations_used(), "seconds": seconds,
            "accepted": info.get("accepted"), "reason": info.get("reason")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chips", default=",".join(CHIPS))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--no-taps", action="store_true", help="the chips cannot read their hidden layers")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    from gift_theory.finetune import load_setting

    ds, arch, w0 = load_setting("digits", "64-32-32-10", 0.05, 0, progress=False)
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
                row = run_one(ds, arch, w0, chip, seed, m, taps=not a.no_taps)
                print(json.dumps(row), flush=True)
                if a.out:
                    with open(a.out, "a") as fh:
                        fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    sys.exit(main())
