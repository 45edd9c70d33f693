"""Interval enclosures (sympy with mpmath.iv, traced JAX functions) contain every value, and
the adaptive sup brackets a known maximum."""

import math

import mpmath

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import sympy as sp
from hypothesis import given
from hypothesis import strategies as st

from proofs_checks._interval import float_up, jaxpr_enclosure, sup_bound, sympy_enclosure


def _f(z):                     # mixes the rules: dot, tanh, exp, integer_pow, division, reductions, sin
    a = jnp.array([[1.0, -2.0], [0.5, 3.0]])
    u = a @ jnp.stack([z, z ** 2]) + jnp.array([0.1, -0.2])
    return jnp.sum(jnp.tanh(u) * jnp.exp(-z) / (1.0 + z ** 2)) + jnp.sin(3.0 * z) ** 3


@given(lo=st.floats(-2.0, 2.0), width=st.floats(1e-6, 1.5), t=st.floats(0.0, 1.0))
def test_jaxpr_enclosure_contains_values(lo, width, t, x64):
    enc = _ENC
    hi = lo + width
    iv = enc(lo, hi)
    z = lo + t * (hi - lo)
    val = float(_f(jnp.float64(z)))
    assert float(iv.lo) <= val <= float(iv.hi)


with jax.enable_x64(True):
    _ENC = jaxpr_enclosure(_f, 0.3)


def test_jaxpr_enclosure_refuses_a_branch_on_the_variable(x64):
    with pytest.raises(ValueError, match="depends on the variable"):
        jaxpr_enclosure(lambda z: jnp.where(z > 0.0, z, -z), 0.5)


def test_sympy_enclosure_and_sup():
    z = sp.Symbol("z", real=True)
    h = sp.sin(5 * z) * z + sp.tanh(z)               # sup over [0, 2] near z ~ 1.9
    enc = sympy_enclosure(h, z)
    for a, b in ((0.0, 0.1), (1.0, 1.7), (0.3, 0.30001)):
        lo, hi = enc(a, b)
        with mpmath.workdps(60):
            for t in np.linspace(a, b, 7):
                val = mpmath.mpf(str(sp.N(h.subs(z, sp.Rational(float(t))), 60)))
                assert lo <= val <= hi
    from scipy.optimize import minimize_scalar

    f = sp.lambdify(z, -sp.Abs(h))
    t0 = max(np.linspace(0, 2, 401), key=lambda t: -f(t))
    grid = -minimize_scalar(f, bounds=(t0 - 0.01, t0 + 0.01), method="bounded", options={"xatol": 1e-12}).fun
    bound = sup_bound(lambda a, b: float_up(max(abs(x) for x in enc(a, b))),
                      lambda t: abs(float(h.subs(z, t))), 0.0, 2.0, rtol=1e-4, max_pieces=2000)
    assert bound.lower <= grid + 1e-12 and grid <= bound.upper <= grid * (1 + 2e-4)


def test_sup_bound_stops_on_thresholds():
    calls = []

    def upper(a, b):
        calls.append((a, b))
        return 1.0 + (b - a)            # sup of a constant 1, overestimated by the width

    b = sup_bound(upper, lambda t: 1.0, 0.0, 1.0, rtol=1e-9, thresholds=[5.0], max_pieces=1000)
    assert b.lower == 1.0 and b.upper < 5.0 and len(calls) == 1
    assert math.isclose(sup_bound(upper, lambda t: 1.0, 0.0, 1.0, rtol=1e-3, max_pieces=4000).upper, 1.0, rel_tol=2e-3)


def test_box_enclosure_contains_values_over_a_box(x64):
    """Several boxed arguments and several outputs: every value at random points of the boxes lies inside."""
    from proofs_checks._interval import IV, box_enclosure

    def f(w, z, c):
        u = jnp.tanh(w @ jnp.array([[1.0, -0.5], [0.3, 2.0]]) * z) + c
        return jnp.sum(u ** 2), jnp.exp(-w * z)

    enc = box_enclosure(f, jnp.zeros(2), 0.5, 1.0, boxed=(0, 1))
    lo, hi = np.array([-0.2, 0.4]), np.array([0.1, 0.45])
    out = enc(IV(lo, hi), IV(np.float64(0.5), np.float64(0.7)), 1.0)
    rng = np.random.default_rng(0)
    for _ in range(50):
        w = lo + rng.uniform(size=2) * (hi - lo)
        z = 0.5 + rng.uniform() * 0.2
        a, b = f(jnp.asarray(w), z, 1.0)
        assert out[0].lo <= float(a) <= out[0].hi
        assert np.all(out[1].lo <= np.asarray(b)) and np.all(np.asarray(b) <= out[1].hi)


def test_krawczyk_certifies_a_simple_zero_and_refuses_a_degenerate_one(x64):
    """F(w) = (w1^2 - 2, w1 w2 - 1): the zero (sqrt 2, 1/sqrt 2) lies in the certified box around its float64
    rounding (independent: the closed form); G(w) = (w1^2, w2) has a double zero at 0: not certified."""
    from proofs_checks._interval import IV, box_enclosure, krawczyk

    F = lambda w: jnp.stack([w[0] ** 2 - 2, w[0] * w[1] - 1])
    jac = lambda w: jnp.array([[2 * w[0], 0.0], [w[1], w[0]]])
    encF, encJ = box_enclosure(F, jnp.ones(2)), box_enclosure(jac, jnp.ones(2))
    c = np.array([math.sqrt(2.0), 1 / math.sqrt(2.0)])
    k = krawczyk(c, encF(IV(c, c)), np.asarray(jac(jnp.asarray(c))), lambda lo, hi: encJ(IV(lo, hi)))
    assert k.unique_zero is True and k.contraction < 1
    exact = np.array([math.sqrt(2), 1 / math.sqrt(2)])                  # the float64 values are within 1 ulp
    assert np.all(np.abs(exact - c) <= k.radius) and np.all(k.radius < 1e-14)
    # far from the zero (the Newton step is large and the box wide) there is no contraction: not certified
    far = np.array([3.0, 3.0])
    k2 = krawczyk(far, encF(IV(far, far)), np.asarray(jac(jnp.asarray(far))), lambda lo, hi: encJ(IV(lo, hi)), tries=2)
    assert k2.unique_zero is None
    G = lambda w: jnp.stack([w[0] ** 2, w[1]])
    encG = box_enclosure(lambda w: jnp.array([[2 * w[0], 0.0], [0.0, 1.0]]), jnp.ones(2))
    z = np.zeros(2)
    k3 = krawczyk(z, box_enclosure(G, jnp.ones(2))(IV(z, z)), np.array([[0.0, 0.0], [0.0, 1.0]]),
                  lambda lo, hi: encG(IV(lo, hi)))
    assert k3.unique_zero is None and "singular" in k3.how
