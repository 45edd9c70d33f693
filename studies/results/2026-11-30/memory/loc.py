import sys, threading, time, ctypes
import jax, numpy as np
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
from gift_theory.lab import _localise as L
from gift_theory.lab._compare import failing_layers
libc = ctypes.CDLL("libc.so.6")
peak = [0.0]
def rss():
    for l in open("/proc/self/status"):
        if l.startswith("VmRSS"): return int(l.split()[1]) / 1e6
def mon():
    while True:
        peak[0] = max(peak[0], rss()); time.sleep(0.05)
threading.Thread(target=mon, daemon=True).start()
def stage(name, f):
    libc.malloc_trim(0); time.sleep(0.1); peak[0] = rss(); before = peak[0]; t0 = time.time()
    out = f(); time.sleep(0.1)
    print(f"{name:22s} before {before:.2f} peak {peak[0]:.2f} after {rss():.2f} GB ({time.time()-t0:.1f} s)", flush=True)
    return out
meas = load_measurement(sys.argv[1])
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
base = session.baseline
steps = stage("one_step", lambda: tuple(session.one_step(base)))
res = stage("residuals", lambda: L.residuals(session.k_step, base, meas, None))
local = stage("one_step_residuals", lambda: L.one_step_residuals(session.k_step, base, meas, {r["layer"]: r["s"] for r in steps}))
ev = stage("layer_evidence", lambda: L.layer_evidence(local))
del local
sig = stage("signatures", lambda: L.signatures(session.k_step, base, meas, res=res))
wh = stage("where_it_fails", lambda: L.where_it_fails(session.k_step, base, meas, res=res))
