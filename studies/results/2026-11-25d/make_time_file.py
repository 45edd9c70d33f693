"""The calibrate time study's file (16-32-16-8, 240 inputs x 64 shots, awgn s=0.1 + shot 0.02, taps, times) saved to npz."""
import sys
import jax, numpy as np
import gift_theory as gt
from gift_theory.lab import simulate_measurement, save_measurement
from studies.calibrate import _network
widths = (16, 32, 16, 8)
arch, params = _network(0, widths)
x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (240, 16)))
meas = simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1, shot=0.02), shots=64, taps=True, times=True)
save_measurement(sys.argv[1], meas)
