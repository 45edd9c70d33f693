"""python cand.py FILE name... : peak RSS of each candidate alone (one thread), after the session."""
import sys
import jax
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
from _rss import rss, stage  # (the stage's peak RSS, as cand.py / loc.py measure it)
meas = load_measurement(sys.argv[1])
print("loaded", rss(), flush=True)
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
for n in sys.argv[2:]:
    e = tuple(n.split("+"))
    stage(n, lambda: session.candidates([(e, None, e, e)]))
