"""python orders_and_shots.py OUT.json [SEEDS]  (run from the project root; PYTHONPATH picks the code)

The time tests' null calibration over acquisition order and shots: null files of the tests' own
plain-numpy simulator (tests/lab/test_time_memory.py's ``sim``: 6-12-4 tanh, awgn 0.05, no
effect; seeds 2000 on, not those the tests were picked from -- but 2030, which became one after
this study), 160 inputs, in the configurations of ``CONFIGS`` (order: random, in blocks -- one
input after the other -- or interleaved; r shots; taps or not); SEEDS files each (default 40).
Per configuration: files on which any class is named (Holm 0.01, as the verdict reads), on which
time_drift is named, and the raw p of map_drift and wander (the smallest over the layers) below
0.01 and 0.05."""
import json
import sys

import numpy as np

sys.path.insert(0, "tests/lab")
from test_time_memory import sim  # noqa: E402

from gift_theory.lab import identify  # noqa: E402
from gift_theory.lab._mechanisms import named  # noqa: E402

CONFIGS = [("random", 4, True), ("random", 8, True), ("blocked", 8, True), ("blocked", 8, False),
           ("blocked", 32, True), ("interleaved", 8, True)]
out, seeds = {}, int(sys.argv[2]) if len(sys.argv) > 2 else 40
for order, r, taps in CONFIGS:
    rec = {"any": 0, "time_drift": 0, "map_drift": [], "wander": []}
    for seed in range(seeds):
        ident = identify(sim(2000 + seed, widths=(6, 12, 4), n=160, r=r, order=order, taps=taps))
        rows = ident.rows()
        cls = {x["class"] for x in rows if named(x, ident.taps)}
        rec["any"] += bool(cls)
        rec["time_drift"] += "time_drift" in cls
        for test in ("map_drift", "wander"):
            ps = [x["p"] for x in rows if x["test"] == test]
            rec[test].append(min(ps) if ps else 1.0)
    key = f"{order} r={r} {'taps' if taps else 'no taps'}"
    row = {"files": seeds, "any class named": rec["any"], "time_drift named": rec["time_drift"]}
    for test in ("map_drift", "wander"):
        v = np.array(rec[test])
        row[f"{test} p<0.01"], row[f"{test} p<0.05"] = int(np.sum(v < 0.01)), int(np.sum(v < 0.05))
    out[key] = row
    print(key, row, file=sys.stderr, flush=True)
json.dump(out, open(sys.argv[1], "w"), indent=1)
