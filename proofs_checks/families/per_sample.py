"""A numeric family with per-sample values (K = 100), outside Theorem 1's hypotheses:
J_i(w, s) = (w1 - a_i)^2/2 + 0.35 (s - 1) w1 + w2^4/4 - w2^2/2 with mean(a) = 0, so the objective
(the mean of the K values) has gradient (w1 + 0.35 (s - 1), w2^3 - w2). At s0 = 1 the given
w0 = (-0.05, 1) has gradient (-0.05, 0): w0 is not critical, and the instance is reported outside
the theorem, never as a counterexample (at w0 = (0, 1) it would be one: the saddle wt = (-0.175, 0)
of J_1.5 is worse than w0). Use with --s0 1 --st 1.5."""

import numpy as np

_a = np.random.default_rng(0).normal(size=100)
_a = _a - _a.mean()


def J(w, s):
    return (w[0] - _a) ** 2 / 2 + 0.35 * (s - 1) * w[0] + w[1] ** 4 / 4 - w[1] ** 2 / 2


w0 = [-0.05, 1.0]
wt = [-0.175, 0.0]
