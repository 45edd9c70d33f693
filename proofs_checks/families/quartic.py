"""The quartic family J_s(w) = A(w) + s^2 B(w) + s^4 C(w) (1-D), s0 = 1, st = 1.1.

A(w) = w^2/2 + A' w, B(w) = B' w, C(w) = C' w with B' = -2.21, C' = 1 and A' = -(B' + C') = 1.21,
so grad J_s(0) = A' + s^2 B' + s^4 C' = (s^2 - 1)(s^2 - 1.21): w0 = 0 is critical at s0 = 1 and
again at st = 1.1. v = d/ds grad J_1(0) = 2 B' + 4 C' = -0.42; (d2/ds2 grad J_zeta)^T v =
-0.42 (2 B' + 12 zeta^2 C'). Printed rhs 2/10.1 = 0.198 > 0.1 = |st - s0| (the condition holds),
corrected rhs 0.0832 < 0.1, and C1 = 0: J_st(w) = w^2/2 has w0 = 0 as its only critical point.
"""

import sympy as sp

s = sp.Symbol("s", positive=True)
w = sp.Symbol("w", real=True)
B1 = sp.Rational(-221, 100)     # B'
C1_ = sp.Integer(1)             # C'
A1 = -(B1 + C1_)                # A' = 1.21
J = (w ** 2 / 2 + A1 * w) + s ** 2 * (B1 * w) + s ** 4 * (C1_ * w)
w0 = 0
