# one diagnosis of a 6-12-6-4 shot-noise chip (tests/lab/test_diagnose.py sizes) in a fresh process; prints wall, CPU and the verdict
import os, sys, time, json
import jax, numpy as np
import gift_theory as gt
from gift_theory.lab import diagnose, simulate_measurement
W=(6,12,6,4)
def chip(spec, seed=0, n=120, r=40, s=0.1):
    arch = gt.Architecture(W); key = jax.random.PRNGKey(seed)
    params = gt.init_params(jax.random.fold_in(key, 1), arch, gain=1.5)
    params = tuple(gt.Layer(Wm, 0.3 * jax.random.normal(jax.random.fold_in(key, 10 + l), b.shape)) for l, (Wm, b) in enumerate(params))
    x = np.asarray(jax.random.uniform(jax.random.fold_in(key, 2), (n, W[0])))
    return simulate_measurement(jax.random.fold_in(key, 3), params, x, gt.Physics.create(s=s, **spec), shots=r, taps=True, times=True)
t=time.perf_counter(); c0=time.process_time()
m=chip({"shot":0.05})
d=diagnose(jax.random.PRNGKey(11), m, candidates=["multiplicative","common_mode","shot"])
print(json.dumps({"wall":time.perf_counter()-t,"cpu":time.process_time()-c0,"first":d.ranking[0].effects[-1],"p":float(d.ranking[0].comparison.p_value)}))
