"""When each stage of a gift command starts and ends, by thread, and JAX's compile events.

    python timeline.py diagnose FILE.npz --seed 4 --quiet --json

The pipeline's stages are wrapped by name (identify, Session.create, rank_candidates, _localise,
the next measurement); the rows go to stderr after the command's own output.
"""
import sys, time, threading, os, functools
T0 = time.perf_counter()
rows = []
def wrap(mod, name, label):
    f = getattr(mod, name)
    @functools.wraps(f)
    def w(*a, **k):
        t = time.perf_counter() - T0
        try:
            return f(*a, **k)
        finally:
            rows.append((label, threading.current_thread().name[:12], t, time.perf_counter() - T0))
    setattr(mod, name, w)
import gift_theory.lab._diagnose as D
import gift_theory.lab._session as S
t_imp = time.perf_counter() - T0
wrap(D, "identify", "identify")
wrap(D, "rank_candidates", "rank_candidates")
wrap(D, "with_alternatives", "with_alternatives")
wrap(D, "_localise", "localise")
wrap(D, "verdict", "verdict")
wrap(D, "mechanisms", "mechanisms")
orig = S.Session.create.__func__
def create(cls, *a, **k):
    t = time.perf_counter() - T0
    try:
        return orig(cls, *a, **k)
    finally:
        rows.append(("session", threading.current_thread().name[:12], t, time.perf_counter() - T0))
S.Session.create = classmethod(create)
D.Session = S.Session
wrap(D, "diagnose", "DIAGNOSE")
import gift_theory.lab._design as DS
wrap(DS, "next_measurement", "design")
import gift_theory.lab as L
wrap(L, "diagnose", "DIAGNOSE_L")
import gift_theory.lab._ambiguity as A
wrap(A, "peers", "peers")
from gift_theory.cli._main import main
from collections import Counter
ev = Counter(); evn = Counter()
from jax import monitoring
def _d(event, secs, **kw):
    ev[event] += secs; evn[event] += 1
monitoring.register_event_duration_secs_listener(_d)
rc = main(sys.argv[1:])
print("\n".join(f"{k}: {ev[k]:.2f} s, {evn[k]}" for k in ev), file=sys.stderr)
print(f"imports {t_imp:.2f}  total {time.perf_counter()-T0:.2f}", file=sys.stderr)
for r in sorted(rows, key=lambda r: r[2]):
    print(f"{r[0]:18s} {r[1]:12s} {r[2]:6.2f} -> {r[3]:6.2f}  ({r[3]-r[2]:.2f})", file=sys.stderr)
