"""raw map_drift / wander p under variants of the across reading's test (monkeypatched)."""
import sys, glob
import numpy as np
import gift_theory.lab._time as T
from gift_theory.lab import load_measurement, identify
variant = sys.argv[1]
orig_ftest = T._ftest
orig_nd = T._neuron_drift
if variant == "robust_across":
    def nd(rd, A1, u1, i):
        f = T._ftest
        T._ftest = lambda C, e, w, dof_used, robust=False: orig_ftest(C, e, w, dof_used, robust=True)
        try:
            return orig_nd(rd, A1, u1, i)
        finally:
            T._ftest = f
    T._neuron_drift = nd
elif variant == "pooled_weights":
    import dataclasses
    def nd(rd, A1, u1, i):
        obs = np.broadcast_to(np.median(rd.obs, axis=0, keepdims=True), rd.obs.shape)
        return orig_nd(dataclasses.replace(rd, obs=obs), A1, u1, i)
    T._neuron_drift = nd
ps = {}
for f in sorted(glob.glob(sys.argv[2])):
    for r in identify(load_measurement(f)).rows():
        if r["test"] in ("map_drift",):
            ps.setdefault((r["test"], r["layer"]), []).append(r["p"])
for k, v in sorted(ps.items()):
    v = np.array(v); print(variant, k, len(v), "p<0.01:", int(np.sum(v < 0.01)), "p<0.05:", int(np.sum(v < 0.05)), "p<1e-3:", int(np.sum(v < 1e-3)))
