# the interval-enclosure calls of the quick ONN instance (tests/proofs/test_checks.py fixture `onn`): count and seconds
import time, jax, collections
import gift_theory as gt
from proofs_checks import _interval
calls = collections.Counter(); tt = collections.Counter()
orig = _interval.box_enclosure
def wrapped(fn, *ex, boxed=(0,)):
    enc = orig(fn, *ex, boxed=boxed)
    name = getattr(fn, "__name__", "?")
    def e(*a):
        t = time.perf_counter(); r = enc(*a); tt[name] += time.perf_counter() - t; calls[name] += 1; return r
    return e
_interval.box_enclosure = wrapped
from proofs_checks import _onn
t=time.perf_counter()
with jax.enable_x64(True):
    s=_onn.setup(quick=True)
print("setup", time.perf_counter()-t, dict(calls), {k: round(v, 2) for k, v in tt.items()})
