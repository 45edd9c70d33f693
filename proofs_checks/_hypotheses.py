"""Hypotheses of the paper's statements, computed on a check's instance.

Each function returns a :func:`proofs_checks._record.hypothesis` whose ``verified`` is the
outcome of a computation (sympy, or arithmetic on the instance's numbers); none is set by hand.
"""

from __future__ import annotations

import functools

import numpy as np
import sympy as sp

from ._record import fmt, hypothesis

_z = sp.Symbol("z", real=True)

#: sympy forms of the activations of ``gift_theory.ACTIVATIONS`` (checked against them numerically
#: by :func:`activation_expression`)
SIGMA_SYMPY = {
    "tanh": sp.tanh(_z),
    "identity": _z,
    "sigmoid": 1 / (1 + sp.exp(-_z)),
    "sin": sp.sin(_z),
}


def activation_expression(activation):
    """The sympy form of an activation (a name of ``gift_theory.ACTIVATIONS`` or a sympy expression in
    one variable), checked against the JAX function at 7 points when it is a name; None when unknown."""
    if isinstance(activation, sp.Basic):
        free = activation.free_symbols
        if len(free) > 1:
            return None
        return activation.subs(next(iter(free)), _z) if free else activation
    expr = SIGMA_SYMPY.get(activation)
    if expr is None:
        return None
    import jax.numpy as jnp

    from gift_theory import ACTIVATIONS

    pts = np.linspace(-3.0, 3.0, 7)
    jx = np.asarray(ACTIVATIONS[activation](jnp.asarray(pts)), np.float64)
    sx = np.array([float(expr.subs(_z, float(t))) for t in pts])
    return expr if np.allclose(jx, sx, rtol=1e-6, atol=1e-6) else None


def _pb_orders(expr, r: int):
    """For k = 0..r: (k, the k-th derivative, continuous on R, growth exponents
    lim log(1 + d_k^2) / log(1 + z^2) at +-inf); each order computed once per expression."""
    return tuple(_pb_order(expr, k) for k in range(r + 1))


@functools.lru_cache(maxsize=64)
def _pb_order(expr, k: int):
    d = sp.diff(expr, _z, k)
    if d.has(sp.Heaviside, sp.DiracDelta, sp.sign, sp.Piecewise):
        cont = False                     # a jump (e.g. the derivative of Max(z, 0))
    else:
        try:
            cont = sp.calculus.util.continuous_domain(d, _z, sp.S.Reals) == sp.S.Reals
        except (NotImplementedError, ValueError, TypeError):
            cont = None
    grow = []
    for end in (sp.oo, -sp.oo):
        g = None
        for form in (d.rewrite(sp.exp), d) if d.has(sp.tanh, sp.sinh, sp.cosh) else (d, d.rewrite(sp.exp)):
            try:
                g = sp.limit(sp.log(1 + form ** 2) / sp.log(1 + _z ** 2), _z, end)
            except (NotImplementedError, ValueError, TypeError):
                g = None
            if g is not None and (g.is_finite or g.is_infinite):
                break
        grow.append(g)
    return k, d, cont, tuple(grow)


def activation_pb(activation, r: int = 2, name: str = "A1", statement: str = "sigma in C^2_PB") -> dict:
    """(A1) sigma in C^r_PB [senen2020almost, Def. 5]: r times differentiable with every derivative
    up to order r continuous on R and polynomially bounded. Decided by sympy on the activation's own
    expression: continuity on R (continuous_domain) and the growth exponent
    q_k = lim_{|z|->inf} log(1 + sigma^(k)(z)^2) / log(1 + z^2): finite -> |sigma^(k)| <= C (1 + z^2)^q
    for large |z| (polynomially bounded, being continuous); infinite -> faster than every polynomial."""
    expr = activation_expression(activation)
    label = activation if isinstance(activation, str) else str(activation)
    if expr is None:
        return hypothesis(name, statement, None, f"{label}: no sympy form known, C^{r}_PB not decided")
    rows = _pb_orders(expr, r)
    ok, bad, undecided, parts = True, [], [], []
    for k, d, cont, grow in rows:
        fin = [g is not None and g.is_finite is True for g in grow]
        inf = [g is not None and (g.is_infinite is True) for g in grow]
        if cont is False or any(inf):
            bad.append(k)
        elif cont is None or not all(fin):
            undecided.append(k)
        parts.append(f"sigma^({k}) = {d}: continuous on R {cont}, growth exponents at +-inf {list(grow)}")
    verified = False if bad else (None if undecided else True)
    return hypothesis(name, statement, verified, f"{label} (sympy): " + "; ".join(parts)
                      + ("" if verified else f" -- orders {bad or undecided} "
                         + ("not continuous or faster than every polynomial" if bad else "not decided")))


def finite_measure_moments(x, y, name: str = "A2", m_max: int = 4) -> dict:
    """(A2) E ||Y||^m ||X||^n < inf for a data measure mu that is the empirical measure of the given
    points: every moment is a finite average, finite iff every point is finite; computed up to m = 4,
    n = 8 as numbers."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    nx, ny = np.linalg.norm(x.reshape(len(x), -1), axis=1), np.linalg.norm(y.reshape(len(y), -1), axis=1)
    moms = [float(np.mean(ny ** m * nx ** n)) for m in range(1, m_max + 1) for n in range(0, 9)]
    ok = bool(np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(moms)))
    return hypothesis(name, "E ||Y||^m ||X||^n < inf", ok,
                      f"mu = the empirical measure of {len(x)} points (max ||x|| = {fmt(float(nx.max()))}, max ||y|| = "
                      f"{fmt(float(ny.max()))}): every moment is an average of finite numbers; largest computed "
                      f"(m <= {m_max}, n <= 8): {fmt(max(moms))}")


def gaussian_linear_moments(d: int, V, name: str = "A2") -> dict:
    """(A2) for x ~ N(0, I_d), y = V x: ||Y|| <= ||V||_2 ||X||, so E ||Y||^m ||X||^n <= ||V||^m E ||X||^(m+n)
    and E ||X||^k = 2^(k/2) Gamma((d + k)/2) / Gamma(d/2) (chi moments) -- finite for every k >= 0 (sympy,
    k a symbol)."""
    k = sp.Symbol("k", nonnegative=True)
    chi = 2 ** (k / 2) * sp.gamma(sp.Rational(d, 2) + k / 2) / sp.gamma(sp.Rational(d, 2))
    finite = bool(chi.is_finite) and bool(sp.gamma(sp.Rational(d, 2)).is_positive)
    vn = float(np.linalg.norm(np.asarray(V, np.float64), 2))
    return hypothesis(name, "E ||Y||^m ||X||^n < inf (m <= 4, every n)", finite and np.isfinite(vn),
                      f"x ~ N(0, I_{d}), y = V x with ||V||_2 = {fmt(vn)}: E||X||^k = {chi} finite for every k >= 0 "
                      f"(sympy: {bool(chi.is_finite)})")


def normal_moments(var, powers=(1, 2, 4), name: str = "integrability",
                   statement: str = "E|f| < inf and E f^2 < inf") -> dict:
    """Finite moments E|B|^p of B ~ N(0, var) for the given p (sympy.stats)."""
    from sympy.stats import E, Normal

    B = Normal("B", 0, sp.sqrt(sp.nsimplify(var)))
    vals = {p: sp.simplify(E(sp.Abs(B) ** p)) for p in powers}
    ok = all(bool(v.is_finite) for v in vals.values())
    return hypothesis(name, statement, ok, f"B ~ N(0, {var}): " + ", ".join(f"E|B|^{p} = {v}" for p, v in vals.items())
                      + " (sympy.stats)")


def distinct_keys(keys, name: str = "A3", statement: str = "fresh independent (x, y) and N each step") -> dict:
    """(A3) on an instance: the PRNG keys that draw each step's data and noise are all distinct (so the
    draws are independent streams). ``keys``: array of raw key data, one row per (run, step, use)."""
    k = np.ascontiguousarray(np.asarray(keys).reshape(len(keys), -1))
    rows = k.view(np.uint64).ravel() if (k.dtype == np.uint32 and k.shape[1] == 2) else None
    n_unique = int(np.unique(rows).size if rows is not None else np.unique(k, axis=0).shape[0])
    return hypothesis(name, statement, n_unique == len(k),
                      f"{n_unique} distinct keys among the {len(k)} that draw the steps' data and noise (threefry "
                      f"streams: distinct keys give independent draws)")


def box_hypothesis(box, flat_params=None, layout=None, name: str = "H",
                   statement: str = "w in the box H of ass:H-is-a-hyperrectangle") -> dict:
    """The box H is a hyperrectangle (W_min < W_max, b_min < b_max) and, when given, the point lies
    in it: ``flat_params`` with ``layout`` a boolean mask (True where the entry is a weight W)."""
    valid = bool(box.W_min < box.W_max and box.b_min < box.b_max)
    inside = True
    detail = f"H = [{box.W_min:g}, {box.W_max:g}] for W, [{box.b_min:g}, {box.b_max:g}] for b: a box {valid}"
    if flat_params is not None:
        w = np.asarray(flat_params, np.float64)
        m = np.asarray(layout, bool)
        inside = bool(np.all((w[m] >= box.W_min) & (w[m] <= box.W_max))
                      and np.all((w[~m] >= box.b_min) & (w[~m] <= box.b_max)))
        detail += (f"; the instance's weights (max |W| = {fmt(float(np.max(np.abs(w[m]))))}, max |b| = "
                   f"{fmt(float(np.max(np.abs(w[~m])) if (~m).any() else 0.0))}) inside: {inside}")
    return hypothesis(name, statement, valid and inside, detail)


def weight_mask(params) -> np.ndarray:
    """Flat boolean mask (order of gift_theory.flatten / ravel_pytree over Layer(W, b)): True at W."""
    out = []
    for layer in params:
        out += [np.ones(np.size(layer.W), bool), np.zeros(np.size(layer.b), bool)]
    return np.concatenate(out)
