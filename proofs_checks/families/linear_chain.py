"""The paper's linear example (ex: linear network) at depth L = 2: scalar chain y = V x,
E[x^2] = m2 = 1, V = 1/2, input noise only, J_s(w1, w2) = m2 (V - w1 w2)^2 + s^2 (w1 w2)^2,
w0 the balanced critical point of J_s0 at s0 = 1/2 (use --s0 0.5). Closed forms:
v = 2 s0 grad B, C1 = 2 s0 (st^2 - s0^2) ||grad B(w0)||^2, corrected rhs 2 s0 = 1."""

import sympy as sp

import linear_case as lc

L, S0 = 2, sp.Rational(1, 2)
_e = lc.symbolic_example(L)
_num = {_e["V"]: sp.Rational(1, 2), _e["m2"]: 1}
s = _e["s"]
w = list(_e["w"])
J = _e["J"].subs(_num)
_c = (_e["m2"] * _e["V"] / (_e["m2"] + _e["s0"] ** 2)).subs(_num).subs(_e["s0"], S0)
w0 = [_c ** sp.Rational(1, L)] * L
