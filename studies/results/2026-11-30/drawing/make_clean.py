"""The clean chip of same_outputs.sh: 8-16-8-4, 120 inputs x 32 shots with taps, awgn only (a
diagnosis that finds nothing missing, so that the commands compute the test's power).

    python make_clean.py OUT.npz
"""
import sys

import jax
import numpy as np

import gift_theory as gt
from gift_theory.lab import simulate_measurement
from gift_theory.lab._io import save_measurement

arch = gt.Architecture((8, 16, 8, 4))
params = gt.init_params(jax.random.PRNGKey(0), arch, gain=1.5)
x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (120, 8)), np.float64)
m = simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.parse(["awgn=0.05"]), shots=32, taps=True)
save_measurement(sys.argv[1], m)
