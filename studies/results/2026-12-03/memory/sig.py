"""python sig.py FILE: the peak RSS of each effect's signature and of the layer evidence on the baseline's residuals."""
import os
import sys
import jax, numpy as np
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
from gift_theory.lab import _localise as L
from gift_theory.effects import REGISTRY
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "2026-11-30", "memory"))  # _rss
from _rss import stage
meas = load_measurement(sys.argv[1])
session = stage("session", lambda: Session.create(jax.random.PRNGKey(4), meas, None, 1))
base = session.baseline
res = stage("residuals", lambda: L.residuals(session.k_step, base, meas, None))
for name, cls in REGISTRY.items():
    if name in base.effects: continue
    stage(name, lambda: cls.signature(res))
for li in range(len(res.layer_ids)):
    stage(f"half_means{li}", lambda: L._half_means(res, li))
stage("evidence", lambda: L.layer_evidence(res))
