import sys, glob
import numpy as np
import gift_theory.lab.identification._layer as L
from gift_theory.lab import load_measurement, identify
seen = {}
orig = L._fit_map
def fm(lay, act, s2, tt=None, **kw):
    if lay.offset is not None:
        seen[lay.layer] = float(np.abs(lay.offset).max())
    return orig(lay, act, s2, tt, **kw)
L._fit_map = fm
for f in sys.argv[1:]:
    seen.clear()
    rows = identify(load_measurement(f)).rows()
    w = {r["layer"]: r["p"] for r in rows if r["test"] == "wander"}
    tm = {r["layer"]: r["p_adj"] for r in rows if r["test"] == "time_map"}
    print(f.split("/")[-1], "wander p", {k: "%.2g" % v for k, v in w.items()}, "path put (max |offset|)", {k: round(v, 3) for k, v in seen.items()},
          "time_map p_adj", {k: "%.2g" % v for k, v in tm.items()})
