"""Exact sympy arithmetic for Theorem 1 on a sympy family: a number read exactly, the exact sign of
a constant (and a proved zero), real roots, the exact sup of |h| over an interval, the real critical
points of J_st and the exact descent test along a line.
"""

from __future__ import annotations

import math

import numpy as np


def _exact(x):
    """A number as an exact sympy number (a float by its decimal text: 0.1 -> 1/10)."""
    import sympy as sp

    if isinstance(x, str):
        return sp.Rational(x)
    if isinstance(x, (float, np.floating)):
        if not math.isfinite(float(x)):
            raise ValueError("not finite")
        return sp.Rational(repr(float(x)))
    return sp.sympify(x)


def _sign(e) -> int:
    """The exact sign of a real constant expression (-1, 0, 1)."""
    import sympy as sp

    e = sp.sympify(e)
    if e == 0:
        return 0
    if e.is_infinite:
        return 1 if e.is_extended_positive else -1
    s = sp.simplify(e)
    if s == 0:
        return 0
    val = sp.N(s, 60)
    if abs(val) > sp.Float("1e-45"):
        return 1 if val > 0 else -1
    try:
        x = sp.Dummy("x")
        if sp.minimal_polynomial(s, x) == x:
            return 0
    except (NotImplementedError, ValueError, sp.PolynomialError):
        pass
    val = sp.N(s, 300)
    return 0 if val == 0 else (1 if val > 0 else -1)


def _zero_proven(e) -> bool:
    """Is the constant expression exactly 0, proved (sympy simplifies it to 0, or its minimal polynomial
    is x)? :func:`_sign` also returns 0 for a value below 10^-300 that it could not prove zero; a
    hypothesis or a refutation that needs an exact zero uses this instead."""
    import sympy as sp

    e = sp.sympify(e)
    if e == 0 or sp.simplify(e) == 0:
        return True
    try:
        x = sp.Dummy("x")
        return sp.minimal_polynomial(sp.simplify(e), x) == x
    except (NotImplementedError, ValueError, sp.PolynomialError):
        return False


def _f(e) -> float:
    import sympy as sp
    e = sp.sympify(e)
    if e.is_infinite:
        return math.inf
    return float(sp.N(e, 30))


def _real_roots(expr, x):
    """The real roots of a polynomial in x: exact CRootOf over the rationals, radicals (sympy
    solve, degree <= 4) when the coefficients are other constants; None when neither works."""
    import sympy as sp

    p = sp.Poly(expr, x)
    try:
        return sorted(set(p.real_roots()), key=_f)
    except (NotImplementedError, sp.PolynomialError):
        pass
    if p.degree() > 4:
        return None
    roots = [r for r in sp.solve(p.as_expr(), x) if _sign(sp.im(r)) == 0]
    return sorted({sp.simplify(sp.re(r)) for r in roots}, key=_f)


def exact_sup_abs(h, z, a, b):
    """sup of |h(z)| over [a, b] exactly: critical points of h in (a, b) (sympy) and the
    endpoints. Returns dict(value, interior, endpoints, points, how) with sympy numbers
    (``interior``: the largest |h| at an interior critical point, or None), or None when
    sympy cannot list the critical points."""
    import sympy as sp

    h = sp.simplify(h)
    ends = [sp.Abs(h.subs(z, a)), sp.Abs(h.subs(z, b))]
    if z not in h.free_symbols:
        v = sp.Abs(h)
        return dict(value=v, interior=v, endpoints=v, points=[], how="constant in zeta")
    dh = sp.together(sp.diff(h, z))
    num, den = sp.fraction(dh)
    crit = None
    how = ""
    if num.is_polynomial(z) and den.is_polynomial(z):
        poles_known = True
        if sp.Poly(den, z).degree() > 0:
            pr = _real_roots(sp.fraction(sp.together(h))[1], z)
            poles_known = pr is not None
            poles = [r for r in pr or [] if _sign(r - a) >= 0 and _sign(b - r) >= 0]
            if poles:
                return dict(value=sp.oo, interior=sp.oo, endpoints=sp.oo, points=poles, how="pole in the interval")
        roots = [] if sp.Poly(num, z).is_zero else _real_roots(num, z)
        if poles_known and roots is not None:
            crit = [r for r in roots if _sign(r - a) > 0 and _sign(b - r) > 0]
            how = f"exact: {len(crit)} critical point(s) of a rational function in (a, b) (real roots) and both ends"
    else:
        S = sp.solveset(sp.diff(h, z), z, sp.Interval.open(a, b))
        if isinstance(S, sp.FiniteSet):
            crit = sorted(S, key=lambda r: _f(r))
            how = f"exact: {len(crit)} critical point(s) in (a, b) (sympy solveset) and both ends"
        elif S is sp.S.EmptySet:
            crit = []
            how = "exact: no critical point in (a, b) (sympy solveset); both ends"
    if crit is None:
        return None
    inner = [sp.Abs(h.subs(z, r)) for r in crit]
    cands = inner + ends
    value = max(cands, key=_f)
    # ties are resolved exactly
    for c in cands:
        if _sign(c - value) > 0:
            value = c
    interior = max(inner, key=_f) if inner else None
    return dict(value=value, interior=interior, endpoints=max(ends, key=_f), points=crit, how=how)


def _critical_points(Jt, ws):
    """Real critical points of J_st: (list of tuples, complete: bool, how)."""
    import sympy as sp

    grads = [sp.together(sp.diff(Jt, x)) for x in ws]
    if len(ws) == 1:
        x = ws[0]
        num, den = sp.fraction(grads[0])
        if num.is_polynomial(x) and den.is_polynomial(x):
            p = sp.Poly(num, x)
            if p.is_zero:
                return [], False, "grad J_st vanishes identically (every w is critical)"
            roots = _real_roots(num, x)
            if roots is None:
                return [], False, "sympy cannot list the real roots of dJ_st/dw (degree > 4, non-rational coefficients)"
            roots = [r for r in roots if _sign(den.subs(x, r)) != 0]
            return [(r,) for r in roots], True, f"real roots of the numerator of dJ_st/dw ({len(roots)})"
        S = sp.solveset(grads[0], x, sp.S.Reals)
        if isinstance(S, sp.FiniteSet):
            return [(r,) for r in S], True, "sympy solveset over the reals"
        if S is sp.S.EmptySet:
            return [], True, "sympy solveset over the reals: no critical point"
        return [], False, f"sympy cannot list the real critical points ({type(S).__name__})"
    if all(sp.fraction(g)[0].is_polynomial(*ws) for g in grads):
        reals = [sp.Dummy(str(x), real=True) for x in ws]
        eqs = [sp.fraction(g)[0].subs(dict(zip(ws, reals))) for g in grads]
        try:
            sols = sp.solve(eqs, reals, dict=True)
        except NotImplementedError:
            return [], False, "sympy cannot solve the polynomial system grad J_st = 0"
        pts, complete, curves = [], True, 0
        for sol in sols:
            vals = tuple(sp.sympify(sol.get(r, r)) for r in reals)
            if any(set(v.free_symbols) & set(reals) for v in vals):
                back = dict(zip(reals, ws))
                # a positive-dimensional component: usable only if J_st is constant on it
                on = sp.simplify(Jt.subs(dict(zip(ws, vals))))
                if on.free_symbols & set(reals):
                    complete = False
                else:
                    curves += 1
                    pts.append(tuple(v.subs(back) for v in vals))
                continue
            if all(_sign(sp.im(v)) == 0 for v in vals):
                pts.append(tuple(sp.re(v) if v.has(sp.I) else v for v in vals))
        return pts, complete, f"sympy solve of the polynomial system ({len(pts)} real component(s)"\
            + (f", {curves} of them curves on which J_st is constant" if curves else "")\
            + ("" if complete else "; a positive-dimensional part with J_st not constant was not enumerated") + ")"
    return [], False, "J_st is not polynomial in several weights: its critical set is not enumerated"


def _line_descent(Jt, ws, w0, v, order: int = 8):
    """Exactly: is there alpha (arbitrarily small) with J_st(w0 - alpha v) < J_st(w0)?
    From the first nonzero Taylor coefficient of phi(alpha) = J_st(w0 - alpha v) - J_st(w0).
    Returns (True/False/None, detail)."""
    import sympy as sp

    a = sp.Symbol("alpha", real=True)
    phi = Jt.subs({x: x0 - a * vi for x, x0, vi in zip(ws, w0, v)}, simultaneous=True) \
        - Jt.subs(dict(zip(ws, w0)))
    for k in range(1, order + 1):
        c = sp.simplify(sp.diff(phi, a, k).subs(a, 0) / sp.factorial(k))
        sg = _sign(c)
        if sg == 0:
            continue
        if k % 2 == 1:
            return True, f"phi(alpha) = J_st(w0 - alpha v) - J_st(w0) = ({c}) alpha^{k} + ...: decreases for small alpha of sign {-sg:+d}"
        if sg < 0:
            return True, f"phi(alpha) = ({c}) alpha^{k} + ...: decreases for every small alpha"
        return False, f"phi(alpha) = J_st(w0 - alpha v) - J_st(w0) = ({c}) alpha^{k} + ... >= 0 near 0"
    return None, f"the first {order} derivatives of phi vanish at 0"
