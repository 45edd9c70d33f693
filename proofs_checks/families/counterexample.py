"""theorem1_condition's counterexample: J_s(w) = w^2/2 + g(s) w, g(s) = v d + u d^2/2, d = s - 2,
with v = 1/2, u = 1; w0 = 0 is critical at s0 = 2. At st = 1: |st - s0| = 1 < printed rhs 2, yet
g(1) = 0, so C1 = 0 and w0 is the minimiser of J_st (w0 = w_t). Use with --s0 2 --st 1."""

import sympy as sp

s = sp.Symbol("s", positive=True)
w = sp.Symbol("w", real=True)
d = s - 2
J = w ** 2 / 2 + (sp.Rational(1, 2) * d + d ** 2 / 2) * w
w0 = 0
