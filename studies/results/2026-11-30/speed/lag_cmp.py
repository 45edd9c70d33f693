"""Every lag test's row, alpha and p of the identification of each FILE, pickled to OUT, with the
lag tests' seconds on stderr: run under two checkouts (PYTHONPATH) and compare the pickles.

    python lag_cmp.py OUT.pkl FILE.npz [FILE.npz ...]
"""
import sys, pickle, time
import numpy as np
import gift_theory.lab._memory as M
from gift_theory.lab import load_measurement
from gift_theory.lab import identification as I
out = {}
orig_deals_p = M.deals_p
rec = []
orig = M.lag_test
def wrapped(*a, **k):
    t=time.perf_counter(); res = orig(*a, **k); rec.append((repr(res.row), res.alpha, res.alpha_se, res.p, time.perf_counter()-t)); return res
M.lag_test = wrapped
import gift_theory.lab.identification._layer as L
if hasattr(L, "lag_test"): L.lag_test = wrapped
for f in sys.argv[2:]:
    rec.clear()
    I.identify(load_measurement(f))
    out[f] = [r[:4] for r in rec]
    print(f, len(rec), "lag s:", round(sum(r[4] for r in rec), 3), file=sys.stderr)
pickle.dump(out, open(sys.argv[1], "wb"))
