import sys, glob, collections, dataclasses
import numpy as np
import gift_theory.lab._time as T
from gift_theory.lab import load_measurement, identify
from gift_theory.lab._mechanisms import named
orig_nd = T._neuron_drift
def nd(rd, A1, u1, i):
    obs = np.broadcast_to(np.median(rd.obs, axis=0, keepdims=True), rd.obs.shape)
    return orig_nd(dataclasses.replace(rd, obs=obs), A1, u1, i)
T._neuron_drift = nd
cnt = collections.Counter()
for f in sorted(glob.glob(sys.argv[1])):
    ident = identify(load_measurement(f))
    cnt[tuple(sorted({r["class"] for r in ident.rows() if named(r, ident.taps)}))] += 1
print(dict(cnt))
