import sys, jax, numpy as np, pickle
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
from gift_theory.lab import _localise as L
meas = load_measurement(sys.argv[1])
s = Session.create(jax.random.PRNGKey(4), meas, None, 1)
res = L.residuals(s.k_step, s.baseline, meas, None)
w = L.where_it_fails(s.k_step, s.baseline, meas, res=res)
sig = L.signatures(s.k_step, s.baseline, meas, res=res)
steps = s.one_step(s.baseline)
loc = L.one_step_residuals(s.k_step, s.baseline, meas, {r["layer"]: r["s"] for r in steps}) if meas.has_taps else res
ev = L.layer_evidence(loc)
pickle.dump((w, sig, ev), open(sys.argv[2], "wb"))
