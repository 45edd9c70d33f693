"""python cand2.py FILE name...: the peak RSS of each candidate's fit, its score, and the whole candidate, one thread."""
import os
import sys
import jax
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "2026-11-30", "memory"))  # _rss
from _rss import rss, stage
meas = load_measurement(sys.argv[1])
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
for n in sys.argv[2:]:
    e = tuple(n.split("+"))
    m = stage(n + " fit", lambda: session.fit(e, start=session.baseline))
    stage(n + " score", lambda: session.score(m))
    stage(n + " all", lambda: session.candidates([(e, None, e, e)]))
