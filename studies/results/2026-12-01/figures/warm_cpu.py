"""Each figure's drawing CPU once warm (the least of four rounds, one process), from the drawings
capture_drawings.py pickled; the code drawn is whichever checkout PYTHONPATH names:

    PYTHONPATH=CHECKOUT python warm_cpu.py DRAWINGS.pkl OUT_PREFIX
"""
import pickle
import sys
import time

import matplotlib

matplotlib.use("Agg")
import gift_theory.lab._drawing as Dr  # noqa: E402

jobs = [(d, n) for d, n in pickle.load(open(sys.argv[1], "rb")) if n.endswith(".png")]
best = {n: float("inf") for _, n in jobs}
for _ in range(4):
    for d, n in jobs:
        t = time.process_time()
        Dr.draw_to(d, f"{sys.argv[2]}_{n}")
        best[n] = min(best[n], time.process_time() - t)
for n in sorted(best):
    print(f"{n:22s} {best[n]:.3f}")
print("sum", round(sum(best.values()), 2))
