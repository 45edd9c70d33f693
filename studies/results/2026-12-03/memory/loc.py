"""python loc.py FILE: the peak RSS of each stage of the localisation, one thread, after the session (_rss.stage)."""
import os
import sys
import jax, numpy as np
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
from gift_theory.lab import _localise as L
from gift_theory.lab._compare import failing_layers
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "2026-11-30", "memory"))  # _rss
from _rss import rss, stage  # (the stage's peak RSS, as cand.py / loc.py measure it)
meas = load_measurement(sys.argv[1])
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
base = session.baseline
steps = stage("one_step", lambda: tuple(session.one_step(base)))

local = stage("one_step_residuals", lambda: L.one_step_residuals(session.k_step, base, meas, {r["layer"]: r["s"] for r in steps}))
ev = stage("layer_evidence", lambda: L.layer_evidence(local))
del local
res = stage("residuals", lambda: L.residuals(session.k_step, base, meas, None))
sig = stage("signatures", lambda: L.signatures(session.k_step, base, meas, res=res))
wh = stage("where_it_fails", lambda: L.where_it_fails(session.k_step, base, meas, res=res))
