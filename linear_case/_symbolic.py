"""The paper's linear example in sympy: a scalar chain of depth L (widths 1-1-..-1),
y = V x, E[x^2] = m2, noise on the input only (paper Example ex: linear network)."""

from __future__ import annotations

import functools

import sympy as sp


def example(L: int):
    """Symbols and closed forms: J_s, grad J, d/ds grad J, d2/ds2 grad J, at the balanced
    critical point w_l = c^{1/L}, c = m2 V / (m2 + s0^2) (V > 0).

    Returns
    -------
    dict with keys s, s0, st, V, m2, w (symbols), J, v, u, C1, printed_rhs, corrected_rhs,
    example_rhs (sympy expressions in s0, st, V, m2 after substituting w0).
    """
    return dict(_example(int(L)))            # a fresh dict of the cached (immutable) expressions


@functools.lru_cache(maxsize=8)
def _example(L: int):
    s, s0, st, V, m2 = sp.symbols("s s0 st V m2", positive=True)
    w = sp.symbols(f"w1:{L + 1}", positive=True)
    W = sp.Mul(*w)
    J = m2 * (V - W) ** 2 + s ** 2 * W ** 2
    grad = sp.Matrix([sp.diff(J, wi) for wi in w])
    c = m2 * V / (m2 + s0 ** 2)
    w0 = {wi: c ** sp.Rational(1, L) for wi in w}
    crit = sp.simplify(grad.subs(s, s0).subs(w0))
    v = sp.simplify(sp.diff(grad, s).subs(s, s0).subs(w0))
    u = sp.simplify(sp.diff(grad, s, 2).subs(w0))             # independent of zeta
    gst = grad.subs(s, st).subs(w0)
    C1 = sp.factor(sp.simplify((gst.T * v)[0]))
    vv = sp.simplify((v.T * v)[0])
    uv = sp.simplify((u.T * v)[0])
    printed = sp.simplify(sp.sqrt(vv) / (uv / 2))
    corrected = sp.simplify(vv / (uv / 2))
    example_rhs = (1 + s0 ** 2 / m2) / (2 * V)
    crit, v, u = (sp.ImmutableMatrix(m) for m in (crit, v, u))    # cached: nobody may change them in place
    return dict(s=s, s0=s0, st=st, V=V, m2=m2, w=w, J=J, critical_residual=crit, v=v, u=u, C1=C1,
                printed_rhs=printed, corrected_rhs=corrected, example_rhs=example_rhs)


def all_noise_critical_points(L: int = 2):
    """Critical points of the ONN-model linear chain 1-1-..-1 with noise at every site
    (mode "all"): J_s = m2 (V - W)^2 + s^2 B(w) with B = W^2 + sum_l P_l^2 (weighted sums)
    + sum_{l<L} P_l^2 (hidden activations), P_l = w_L...w_{l+1}.

    Returns (J, solutions of grad J = 0 from sympy, the rescaling derivative
    d/dt J(t w_1, w_2/t, w_3, ...) at t = 1, which is -2 s^2 (2 P_1^2) < 0 unless P_1 = 0).
    """
    s, V, m2, t = sp.symbols("s V m2 t", positive=True)
    w = sp.symbols(f"w1:{L + 1}", real=True)
    W = sp.Mul(*w)
    tail = lambda l: sp.Mul(*w[l:])   # P_l = w_L ... w_{l+1}
    B = W ** 2 + sum(tail(l) ** 2 for l in range(1, L + 1)) + sum(tail(l) ** 2 for l in range(1, L))
    J = m2 * (V - W) ** 2 + s ** 2 * B
    sols = sp.solve([sp.diff(J, wi) for wi in w], w, dict=True)
    if L < 2:
        return J, sols, sp.Integer(0)
    scaled = J.subs({w[0]: t * w[0], w[1]: w[1] / t}, simultaneous=True)
    rescale = sp.simplify(sp.diff(scaled, t).subs(t, 1))
    return J, sols, rescale
