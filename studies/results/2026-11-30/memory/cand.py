"""python cand.py FILE name... : peak RSS of each candidate alone (one thread), after the session."""
import sys, threading, time, ctypes
import jax
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
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
print("loaded", rss(), flush=True)
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
for n in sys.argv[2:]:
    e = tuple(n.split("+"))
    stage(n, lambda: session.candidates([(e, None, e, e)]))
