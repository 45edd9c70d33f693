"""Theorem 1 (thm:FT-is-needed) on any family J_s(w): the printed and the corrected
condition, C1, and whether the conclusion holds at (s0, st) -- reference §5b.

A family is either

* **sympy**: a symbol ``s``, weights ``w`` (a symbol or a list of symbols), an expression
  ``J`` in s and w (any polynomial or analytic form) and ``w0`` (a number or a list, a
  critical point of J at s = s0). Everything is exact: derivatives, ||v||, C1, the sup over
  zeta of |(d2/ds2 grad J_zeta(w0))^T v| (critical points of a function of one variable by
  sympy, endpoints included; if sympy cannot list them, a rigorous interval bound) and the
  critical points of J_st (real roots, or sympy's solution of a polynomial system).
* **numeric**: a JAX-differentiable ``J(w, s)`` returning a scalar or per-sample values
  (shape (K,)) and an array ``w0``. The objective is the mean of the K values -- a finite
  mean, so its gradient and every other derivative are computed, not estimated. Every number
  that decides anything is enclosed by float64 interval arithmetic on the traced computation
  (:mod:`proofs_checks._interval`): the gradient at w0 (w0 is critical only if Krawczyk's
  test proves an exact critical point in a small box around it, and every decision is then
  taken on that box), ||v||^2, C1, and the sup over zeta (centred form with adaptive
  bisection). An optional ``wt`` (an array or a list of arrays) names candidate critical
  points of J_st; the conclusion is tested on those shown critical the same way.

The condition of the paper (ass:Laplacian-properties) and the corrected one::

    printed    0 < |st - s0| < ||v||_2   / (1/2 |(d2/ds2 grad J_zeta(w0))^T v|)  for all zeta in (s0^st, s0vst)
    corrected  0 < |st - s0| < ||v||_2^2 / (1/2 sup_zeta |(d2/ds2 grad J_zeta(w0))^T v|)   (zeta in [s0^st, s0vst])

with v = d/ds grad J_s0(w0). Under the corrected condition (and grad J_s0(w0) = 0),
C1 = grad J_st(w0)^T v != 0 with the sign of st - s0 (integral remainder of the scalar
h(s) = v^T grad J_s(w0)). The conclusion of Theorem 1 is "w0 != w_t and J_st(w_t) <
J_st(w0)" for w_t in {grad J_st = 0}; the condition is only sufficient, so "the sufficient
condition is not met" is never reported as "fails".
"""

from __future__ import annotations

import math
import os
import runpy
from typing import Any, NamedTuple

import numpy as np

from ._interval import float_up, sup_bound, sympy_enclosure
from ._record import decide, fmt

#: what a family file must define (reference §5b)
FAMILY_NAMES = ("s", "w", "J", "w0")


class Family(NamedTuple):
    """A J_s family. ``kind`` is "sympy" or "numeric"; ``wt`` optional candidate critical points of
    J_st; ``certify`` (numeric, optional) a callable ``(w_flat, s) -> dict(verified, radius, how)``
    or None that proves a degenerate critical point exactly (where Krawczyk's test cannot)."""

    kind: str
    J: Any
    w0: Any
    s: Any = None
    w: tuple = ()
    wt: Any = None
    name: str = "family"
    certify: Any = None


class FamilyError(ValueError):
    """A family that breaks the contract of reference §5b (one line, names the rule)."""

    def __init__(self, message):
        super().__init__(" ".join(str(message).split()))      # one line, whatever the cause's text


# --------------------------------------------------------------------------------------
# building and loading families
# --------------------------------------------------------------------------------------
def family(J, w0, *, s=None, w=None, wt=None, name: str = "family", certify=None) -> Family:
    """A :class:`Family` from sympy objects (``s``, ``w``, expression ``J``) or from a
    JAX-differentiable ``J(w, s)`` and an array ``w0`` (``certify``: see :class:`Family`)."""
    import sympy as sp

    if isinstance(J, sp.Basic):
        if s is None or w is None:
            raise FamilyError("a sympy family needs the symbol `s` and the weights `w`")
        if not isinstance(s, sp.Symbol):
            raise FamilyError("`s` must be a sympy Symbol")
        ws = tuple(w) if isinstance(w, (list, tuple)) else (w,)
        if not ws or not all(isinstance(x, sp.Symbol) for x in ws):
            raise FamilyError("`w` must be a sympy Symbol or a list of Symbols")
        if s in ws:
            raise FamilyError("`s` must not be one of the weights `w`")
        extra = J.free_symbols - set(ws) - {s}
        if extra:
            raise FamilyError(f"`J` depends on symbols other than s and w: {', '.join(sorted(map(str, extra)))}")
        undef = J.atoms(sp.core.function.AppliedUndef)
        if undef:
            raise FamilyError(f"`J` contains undefined functions: {', '.join(sorted(map(str, undef)))}")
        if J.has(sp.I):
            raise FamilyError("`J` must be real (it contains the imaginary unit I)")
        kinks = [f.__name__ for f in (sp.Abs, sp.sign, sp.Heaviside, sp.Piecewise, sp.Max, sp.Min, sp.floor,
                                      sp.ceiling) if J.has(f)]
        if kinks:
            raise FamilyError(f"`J` must be smooth in s and w (Theorem 1 differentiates it three times); it "
                              f"contains {', '.join(kinks)}")
        w0s = list(w0) if isinstance(w0, (list, tuple)) else [w0]
        if len(w0s) != len(ws):
            raise FamilyError(f"`w0` has {len(w0s)} entries but `w` has {len(ws)}")
        try:
            w0s = tuple(_exact(x) for x in w0s)
        except (TypeError, ValueError, sp.SympifyError):
            raise FamilyError("`w0` must be numbers (or sympy numbers)") from None
        if any(x.free_symbols for x in w0s):
            raise FamilyError("`w0` must be numbers, not expressions with symbols")
        return Family("sympy", J, w0s, s, ws, wt, name)
    if callable(J):
        try:
            w0a = np.asarray(w0, dtype=np.float64)
        except (TypeError, ValueError):
            raise FamilyError("`w0` of a numeric family must be an array of numbers") from None
        if w0a.ndim == 0:
            w0a = w0a.reshape(1)
        wts = None
        if wt is not None:
            try:            # one point of the shape of w0 (e.g. wt = [1.5, 0]), or a list of points
                one = np.asarray(wt, np.float64)
                lst = [wt] if one.size == w0a.size else (list(wt) if isinstance(wt, (list, tuple)) else [wt])
            except (TypeError, ValueError):
                lst = list(wt) if isinstance(wt, (list, tuple)) else [wt]
            try:
                wts = [np.asarray(x, np.float64).reshape(w0a.shape) for x in lst]
            except (TypeError, ValueError):
                raise FamilyError(f"`wt` must be arrays of the shape of w0 {w0a.shape}") from None
        return Family("numeric", J, w0a, None, (), wts, name, certify)
    raise FamilyError("`J` must be a sympy expression in s and w, or a callable J(w, s)")


def load_family(path: str) -> Family:
    """Load a family file (reference §5b); a broken file raises :class:`FamilyError`."""
    if not os.path.isfile(path):
        raise FamilyError(f"{path}: no such file")
    try:
        ns = runpy.run_path(path, run_name="gift_family")
    except (Exception, SystemExit) as exc:  # the user's file failed to run (or called exit)
        raise FamilyError(f"{path}: failed to run: {type(exc).__name__}: {exc}") from None
    if "J" not in ns or "w0" not in ns:
        raise FamilyError(f"{path}: must define `J` and `w0` (and `s`, `w` for a sympy family)")
    try:
        return family(ns["J"], ns["w0"], s=ns.get("s"), w=ns.get("w"), wt=ns.get("wt"),
                      name=os.path.basename(path), certify=ns.get("certify"))
    except FamilyError as exc:
        raise FamilyError(f"{path}: {exc}") from None


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


# --------------------------------------------------------------------------------------
# exact arithmetic helpers
# --------------------------------------------------------------------------------------
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


def _lt(a, b) -> bool:
    return _sign(sp_sub(b, a)) > 0


def sp_sub(a, b):
    import sympy as sp
    return sp.sympify(a) - sp.sympify(b)


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


# --------------------------------------------------------------------------------------
# the checker
# --------------------------------------------------------------------------------------
def theorem1(fam: Family, s0, st, *, confidence: float = 0.95, rtol: float = 0.02, max_pieces: int = 64) -> dict:
    """Theorem 1 on the family ``fam`` at (s0, st).

    Returns
    -------
    dict with (JSON-ready) ``printed_condition`` / ``corrected_condition`` in
    {"holds", "not met", "undecided"}, ``printed_rhs`` / ``corrected_rhs`` / ``C1`` /
    ``v_norm2`` / ``sup_abs_d2_dot_v`` as {"value", "lo", "hi"} (lo = hi for exact families),
    ``hypotheses`` (each with ``verified``), ``conclusion`` in {"holds", "fails",
    "inconclusive"}, ``descent`` (is there a small step along v that lowers J_st), and an
    ``evidence`` sentence. :func:`contract_json` keeps the reference §5b keys.
    """
    if fam.kind == "sympy":
        return _theorem1_sympy(fam, s0, st, rtol=rtol, max_pieces=max_pieces)
    return _theorem1_numeric(fam, s0, st, confidence=confidence, rtol=rtol, max_pieces=max_pieces)


def inside_hypotheses(res: dict):
    """True when every hypothesis of Theorem 1 is verified on the instance, False when one is
    computed false (the instance lies outside the theorem), None when one is undecided."""
    vs = [h["verified"] for h in res["hypotheses"] if h.get("needed_for_refutation", True)]
    return False if any(v is False for v in vs) else (True if all(v is True for v in vs) else None)


def contract_json(res: dict) -> dict:
    """The reference §5b object of a :func:`theorem1` result, plus ``inside_hypotheses``
    (True / False / None, see :func:`inside_hypotheses`) and ``counterexample`` (True only when
    the conclusion fails on an instance inside every hypothesis: a counterexample to Theorem 1
    as printed)."""
    inside = inside_hypotheses(res)
    return {"printed_condition": res["printed_condition"] == "holds",
            "corrected_condition": res["corrected_condition"] == "holds",
            "C1": float(res["C1"]["value"]), "conclusion": res["conclusion"], "evidence": res["evidence"],
            "hypotheses": res["hypotheses"], "inside_hypotheses": inside,
            "counterexample": bool(inside is True and res["conclusion"] == "fails")}


def _hyp(name, statement, verified, detail):
    from ._record import hypothesis
    return hypothesis(name, statement, verified, str(detail))


def _iv(value, lo=None, hi=None):
    value = float(value)
    return {"value": value, "lo": value if lo is None else float(lo), "hi": value if hi is None else float(hi)}


def _theorem1_sympy(fam: Family, s0, st, *, rtol, max_pieces) -> dict:
    import sympy as sp

    s, ws, J = fam.s, fam.w, fam.J
    s0e, ste = _exact(s0), _exact(st)
    sub0 = dict(zip(ws, fam.w0))
    grad = [sp.diff(J, x) for x in ws]
    g0 = [sp.simplify(g.subs(sub0).subs(s, s0e)) for g in grad]
    v = [sp.simplify(sp.diff(g, s).subs(sub0).subs(s, s0e)) for g in grad]
    vv = sp.simplify(sum(x ** 2 for x in v))
    vn = sp.sqrt(vv)
    z = sp.Symbol("zeta", real=True)
    h = sp.simplify(sum(sp.diff(g, s, 2).subs(sub0).subs(s, z) * x for g, x in zip(grad, v)))
    gst = [sp.simplify(g.subs(sub0).subs(s, ste)) for g in grad]
    for what, vals in (("grad J_s0(w0)", g0), ("d/ds grad J_s0(w0)", v), ("grad J_st(w0)", gst)):
        for x in vals:
            num = sp.N(x, 30)
            if not (num.is_real and num.is_finite):
                raise FamilyError(f"{what} is not a finite real number ({x}): J must be real and smooth near w0")
    C1 = sp.simplify(sum(a * b for a, b in zip(gst, v)))
    gap = sp.Abs(ste - s0e)
    a, b = (s0e, ste) if s0e <= ste else (ste, s0e)
    zero_g0 = [_sign(x) == 0 for x in g0]
    proven_g0 = [z and _zero_proven(x) for z, x in zip(zero_g0, g0)]
    critical0 = False if not all(zero_g0) else (True if all(proven_g0) else None)      # None: |g| < 1e-300, unproven
    hint = ""
    big = max(abs(float(sp.N(x, 30))) for x in g0) if g0 else 0.0
    if critical0 is False and big < 1e-8:
        # a decimal w0 (a float solution) is a critical point only to a float's precision: the exact
        # check needs it exact, and says so rather than a bare "not critical"
        hint = (f"; |grad J_s0(w0)| = {big:.2g}: zero to a float's precision, not exactly -- a decimal w0 is "
                f"rounded; give it exactly (sp.Rational, sp.sqrt, or a root from sp.solve(sp.diff(J, w).subs(s, "
                f"s0), w)) for the exact check, or write the family as a numeric J(w, s), which is checked with "
                f"rigorous interval enclosures and Krawczyk's test")
    hyps = [_hyp("s_positive", "s0, st in (0, inf)", bool(s0e > 0 and ste > 0), f"s0 = {s0e}, st = {ste}"),
            _hyp("st_ne_s0", "0 < |st - s0| (ass:Laplacian-properties)", _sign(gap) > 0, f"|st - s0| = {gap}"),
            _hyp("w0_critical", "w0 in {grad J_s0 = 0} (ass:Nonempty-minimizer-sets)", critical0,
                 f"grad J_s0(w0) = {g0 if len(g0) > 1 else g0[0]} (exact, the whole gradient){hint}")]
    # the sup over zeta
    sup = None
    if gap != 0:
        ex = exact_sup_abs(h, z, a, b)
        if ex is not None:
            M, M_int, M_end = ex["value"], ex["interior"], ex["endpoints"]      # exact sup, interior / ends
            sup = dict(lo=M, hi=M, how=ex["how"], exact=True)
        else:
            enc = sympy_enclosure(h, z)

            def upper_on(p, q):
                lo_, hi_ = enc(p, q)
                return float_up(max(abs(lo_), abs(hi_)))

            lo_end, hi_end = np.nextafter(float(a), -np.inf), np.nextafter(float(b), np.inf)   # cover the ends
            bound = sup_bound(upper_on, lambda t: float(abs(h.subs(z, sp.Rational(t)).evalf(30))) * (1 - 1e-25),
                              lo_end, hi_end, rtol=rtol, max_pieces=max_pieces)
            sup = dict(lo=sp.Float(bound.lower, 30), hi=sp.Float(bound.upper, 30), exact=False,
                       how=f"rigorous bound: mpmath interval arithmetic with bisection into {bound.pieces} pieces")
            M_int = M_end = None
    # conditions
    printed, corrected, prhs, crhs = _conditions_exact(vv, vn, gap, sup, M_int if sup and sup["exact"] else None,
                                                       M_end if sup and sup["exact"] else None)
    hyps.append(_hyp("printed_condition", "ass:Laplacian-properties as printed", printed == "holds", printed))
    # the conclusion: critical points of J_st
    Jt = J.subs(s, ste)
    pts, complete, how_pts = _critical_points(Jt, ws)
    J0 = Jt.subs(sub0)
    diffs = [sp.simplify(Jt.subs(dict(zip(ws, p)), simultaneous=True) - J0) for p in pts]
    signs = [_sign(d) for d in diffs]
    # a point refutes when J_st(w_t) - J_st(w0) > 0, or = 0 proved exactly (a value below 1e-300 is not enough)
    bad = [i for i, sg in enumerate(signs) if sg > 0 or (sg == 0 and _zero_proven(diffs[i]))]
    hyps.append(_hyp("wt_exists", "{grad J_st = 0} nonempty (ass:Nonempty-minimizer-sets)",
                     bool(pts) if (pts or complete) else None, how_pts))
    conclusion = decide(fails=bool(bad), holds=bool(pts) and complete and all(sg < 0 for sg in signs))
    descent, descent_detail = _line_descent(Jt, ws, fam.w0, v) if any(_sign(x) for x in v) else \
        (False, "v = d/ds grad J_s0(w0) = 0: no direction")
    res = {
        "family": "sympy", "name": fam.name, "s0": _f(s0e), "st": _f(ste), "gap": _f(gap), "confidence": 1.0,
        "exact": True,
        "v": [str(x) for x in v], "v_norm2": _iv(_f(vv)), "d2_dot_v": str(h),
        "sup_abs_d2_dot_v": None if sup is None else {"value": _f(sup["hi"]), "lo": _f(sup["lo"]), "hi": _f(sup["hi"]),
                                                      "how": sup["how"]},
        "printed_rhs": prhs, "corrected_rhs": crhs,
        "printed_condition": printed, "corrected_condition": corrected,
        "C1": _iv(_f(C1)), "C1_exact": str(C1),
        "critical_points_st": [[str(x) for x in p] for p in pts], "critical_points_complete": complete,
        "J_st_wt_minus_J_st_w0": [_f(d) for d in diffs],
        "descent": {"exists": descent, "detail": descent_detail},
        "hypotheses": hyps, "conclusion": conclusion,
    }
    pts_text = "; ".join(f"({', '.join(p)}): {fmt(d)}" for p, d in zip(res["critical_points_st"],
                                                                    res["J_st_wt_minus_J_st_w0"]))
    res["evidence"] = _evidence(res, extra=f"C1 = {C1} (exact)" + (f"; sup over zeta {sup['how']}" if sup else "")
                                + f"; critical points of J_st ({how_pts}; "
                                  f"{'complete' if complete else 'not complete'}) with J_st(w_t) - J_st(w0): "
                                  f"{pts_text or 'none found'}")
    return res


def _conditions_exact(vv, vn, gap, sup, M_int, M_end):
    """Printed / corrected condition from exact ||v||^2 and the sup bracket [lo, hi]."""
    import sympy as sp

    if _sign(gap) == 0:
        nan = {"value": math.nan, "lo": math.nan, "hi": math.nan}
        return "not met", "not met", nan, nan
    if _sign(vv) == 0:
        zero = {"value": 0.0, "lo": 0.0, "hi": 0.0}
        return "not met", "not met", zero, zero          # 0/0: v = 0 gives no bound and no direction
    lo, hi = sup["lo"], sup["hi"]

    def rhs(num, M):
        return sp.oo if _sign(M) == 0 else num / (M / 2)

    prhs = {"value": _f(rhs(vn, hi)), "lo": _f(rhs(vn, hi)), "hi": _f(rhs(vn, lo))}
    crhs = {"value": _f(rhs(vv, hi)), "lo": _f(rhs(vv, hi)), "hi": _f(rhs(vv, lo))}
    if M_int is not None or M_end is not None:         # exact sup: the printed "for all zeta in the open interval"
        ok_int = M_int is None or _sign(vn - gap * M_int / 2) > 0
        ok_end = _sign(vn - gap * M_end / 2) >= 0
        printed = "holds" if (ok_int and ok_end) else "not met"
        corrected = "holds" if _sign(vv - gap * hi / 2) > 0 else "not met"
        return printed, corrected, prhs, crhs

    def status(num):
        if _sign(num - gap * hi / 2) > 0:
            return "holds"
        if _sign(num - gap * lo / 2) <= 0:
            return "not met"
        return "undecided"

    return status(vn), status(vv), prhs, crhs


def _evidence(res: dict, extra: str = "") -> str:
    """One sentence: the conditions, C1, the conclusion and what the combination means."""
    iv = lambda d: (fmt(d["value"]) if d["lo"] == d["hi"] else f"{fmt(d['value'])} [{fmt(d['lo'])}, {fmt(d['hi'])}]")
    conf = "" if res["exact"] else f" (simultaneous intervals at confidence 1 - {1 - res['confidence']:.2g})"
    crit0 = next(h for h in res["hypotheses"] if h["name"] == "w0_critical")
    inside = inside_hypotheses(res)
    parts = [f"{res['family']} family {res['name']} at s0 = {res['s0']:g}, st = {res['st']:g}{conf}: "
             f"|st - s0| = {fmt(res['gap'])}; printed rhs {iv(res['printed_rhs'])} -> printed condition "
             f"{res['printed_condition']}; corrected rhs {iv(res['corrected_rhs'])} -> corrected condition "
             f"{res['corrected_condition']}; C1 = {iv(res['C1'])}"]
    if res["gap"] == 0:
        parts.append("st = s0: outside the theorem's hypotheses (0 < |st - s0|)")
    if crit0["verified"] is False:
        parts.append(f"w0 is not a critical point of J_s0 ({crit0['detail']}): outside the theorem's hypotheses")
    elif crit0["verified"] is None:
        parts.append(f"w0 is not verified to be a critical point of J_s0 ({crit0['detail']}): the theorem's "
                     f"hypotheses are not verified on this instance")
    parts.append(f"conclusion (w0 != w_t and J_st(w_t) < J_st(w0) for every critical point w_t of J_st): "
                 f"{res['conclusion']}")
    if res["conclusion"] == "fails":
        if res["printed_condition"] == "holds" and inside is True:
            parts.append("the printed condition holds and the conclusion fails: a counterexample to Theorem 1 as printed")
        else:
            bad = [h["name"] for h in res["hypotheses"] if h["verified"] is not True]
            parts.append(f"{'outside' if inside is False else 'not verified to be inside'} the theorem's hypotheses "
                         f"({', '.join(bad)} {'false' if inside is False else 'not verified'}), so this is no "
                         f"counterexample to the theorem")
    elif res["printed_condition"] != "holds":
        parts.append("the sufficient condition is not met: the theorem says nothing here")
    d = res["descent"]
    parts.append(("a small step along v lowers J_st (w0 is not a minimiser of J_st)" if d["exists"] else
                  "no small step along v lowers J_st" if d["exists"] is False else
                  "a descent step along v is not confirmed") + f" ({d['detail']})")
    if extra:
        parts.append(extra)
    return "; ".join(parts)


# --------------------------------------------------------------------------------------
# numeric families (JAX): finite means, rigorous interval enclosures
# --------------------------------------------------------------------------------------
class _Numeric(NamedTuple):
    per_sample: Any      # w (P,), s -> (K,)
    K: int
    shape: tuple


def _numeric(fam: Family) -> _Numeric:
    import jax
    import jax.numpy as jnp

    shape = fam.w0.shape

    def per_sample(wf, s):
        out = jnp.asarray(fam.J(wf.reshape(shape), s), jnp.float64)
        return out if out.ndim else out.reshape(1)

    with jax.enable_x64(True):
        try:
            raw = jax.eval_shape(lambda wf, s_: fam.J(wf.reshape(shape), s_), jnp.asarray(fam.w0.ravel()),
                                 jnp.float64(1.0))
        except Exception as exc:
            raise FamilyError(f"J(w0, s) failed: {type(exc).__name__}: {exc}") from None
        if not hasattr(raw, "shape") or len(raw.shape) > 1:
            raise FamilyError(f"J(w, s) must return a scalar or per-sample values of shape (K,); it returned shape "
                              f"{tuple(getattr(raw, 'shape', ())) if hasattr(raw, 'shape') else type(raw).__name__}")
        try:
            out = per_sample(jnp.asarray(fam.w0.ravel()), jnp.float64(1.0))
        except Exception as exc:
            raise FamilyError(f"J(w0, s) failed: {type(exc).__name__}: {exc}") from None
    if out.shape[0] < 1:
        raise FamilyError("J(w, s) returned no per-sample values (shape (0,))")
    return _Numeric(per_sample, int(out.shape[0]), shape)


class _Programs:
    """The float64 functions of a numeric family's objective J_s(w) = mean of its K per-sample
    values (a finite mean: its derivatives are exact, not estimates) and their interval
    enclosures (:func:`proofs_checks._interval.box_enclosure`), each compiled on first use."""

    def __init__(self, num: _Numeric, w0, s0):
        import jax
        import jax.numpy as jnp

        f = num.per_sample
        self.J = lambda w, s: jnp.mean(f(w, s))
        self.grad = jax.grad(self.J)
        self.ds = jax.jacfwd(self.grad, argnums=1)
        self.hess = jax.hessian(self.J)

        def F2(w, zeta):                             # d2/ds2 grad J_s(w) by nested forward differentiation
            d1 = lambda s_: jax.jvp(lambda q: self.grad(w, q), (s_,), (jnp.ones((), jnp.float64),))[1]
            return jax.jvp(d1, (zeta,), (jnp.ones((), jnp.float64),))[1]

        def curvature(w, s, u):                      # u^T Hess J_s(w) u = d2/da2 J_s(w + a u) at a = 0
            line = lambda a: self.J(w + a * u, s)
            return jax.jvp(lambda a: jax.jvp(line, (a,), (jnp.ones((), jnp.float64),))[1],
                           (jnp.zeros((), jnp.float64),), (jnp.ones((), jnp.float64),))[1]

        def point(w, zeta, sa, sb, u):               # every quantity but the Hessian, in one program
            return (self.J(w, sa), self.grad(w, sa), self.grad(w, sb), self.ds(w, sb), curvature(w, sa, u),
                    F2(w, zeta))

        self.F2, self.point = F2, point
        self._w0 = jnp.asarray(w0, jnp.float64)
        self._s0 = jnp.float64(s0)
        self._enc = {}
        self._jit = {}

    def f(self, name):
        """The jitted float64 function ``name``."""
        import jax

        if name not in self._jit:
            self._jit[name] = jax.jit(getattr(self, name))
        return self._jit[name]

    def enc(self, name):
        """The interval enclosure of ``name``: "point" (boxed in w and zeta) or "hess" (boxed in w). Two
        compiled programs in all: their compilation dominates their cost."""
        import jax.numpy as jnp

        from ._interval import box_enclosure

        if name not in self._enc:
            w, s = self._w0, self._s0
            if name == "point":
                self._enc[name] = box_enclosure(self.point, w, s, s, s, jnp.zeros_like(w), boxed=(0, 1))
            else:
                self._enc[name] = box_enclosure(getattr(self, name), w, s)
        return self._enc[name]

    def at(self, box, sa, sb=None, u=None, zeta=None):
        """Enclosures (J(w, sa), grad J(w, sa), grad J(w, sb), d/ds grad J(w, sb), u^T Hess J_sa(w) u,
        d2/ds2 grad J(w, zeta)) for every w in ``box`` and zeta in the interval ``zeta`` (lo, hi)."""
        from ._interval import IV

        sb = sa if sb is None else sb
        u = np.zeros(np.shape(box.lo)) if u is None else u
        z = (sa, sa) if zeta is None else zeta
        return self.enc("point")(box, IV(np.float64(z[0]), np.float64(z[1])), np.float64(sa), np.float64(sb),
                                 np.asarray(u, np.float64))

    def J_enc(self, box, s):
        return self.at(box, s)[0]

    def grad_enc(self, box, s):
        return self.at(box, s)[1]

    def F2_enc(self, box, lo, hi=None):
        return self.at(box, lo, zeta=(lo, lo if hi is None else hi))[5]


def _box(w, r=None):
    from ._interval import IV

    w = np.asarray(w, np.float64)
    r = np.zeros_like(w) if r is None else np.asarray(r, np.float64)
    return IV(np.nextafter(w - r, -np.inf) if np.any(r) else w.copy(), np.nextafter(w + r, np.inf) if np.any(r) else w.copy())


def critical_certificate(progs: _Programs, w, s, certify=None) -> dict:
    """Is w a critical point of J_s (the family's objective, the mean of its per-sample values)?
    Decided by computation, never by a test that merely fails to reject:

    * **False** when the gradient enclosure over every point within 2 ulp of w excludes 0 in some
      coordinate: the exact gradient is nonzero there (no critical point that w is the float64
      rounding of);
    * **True** when Krawczyk's test (:func:`proofs_checks._interval.krawczyk`, the interval
      Hessian over the box) proves exactly one critical point w* in the box w +- r -- every
      quantity that decides anything is then enclosed over that box, so it holds at w*; or, when
      the Hessian is singular (a degenerate critical point, where no such test can succeed), when
      the family's own ``certify(w, s)`` proves one (e.g. by symmetry, exactly);
    * **None** otherwise: not verified, so no refutation can rest on it.

    Returns dict(verified, radius (P,), max_abs_grad, text).
    """
    from ._interval import IV, iv_mag, iv_mid_rad, iv_mig, krawczyk

    w = np.asarray(w, np.float64)
    ulp = 2 * np.spacing(np.abs(w) + 1e-300)
    genc = progs.grad_enc(IV(w - ulp, w + ulp), s)
    g = iv_mid_rad(progs.grad_enc(_box(w), s))[0]
    out = np.nonzero(iv_mig(genc) > 0)[0]
    head = f"max |grad J_s(w)| = {fmt(float(np.max(np.abs(g))))} (float64)"
    if out.size:
        i = int(out[np.argmax(iv_mig(genc)[out])])
        return dict(verified=False, radius=np.zeros_like(w), max_abs_grad=float(np.max(np.abs(g))),
                    text=f"{head}; on every point within 2 ulp of w the gradient is nonzero: {out.size} coordinate(s) "
                         f"whose enclosure excludes 0 (e.g. coordinate {i}: [{fmt(float(genc.lo[i]), 6)}, "
                         f"{fmt(float(genc.hi[i]), 6)}]), so w is not a critical point (exact: the objective is a "
                         f"finite mean, its gradient is computed, not estimated)")
    H = np.asarray(progs.f("hess")(w, np.float64(s)))
    kr = krawczyk(w, progs.grad_enc(_box(w), s), H,
                  lambda lo, hi: progs.enc("hess")(IV(lo, hi), np.float64(s)))
    width = f"gradient enclosure half-width {fmt(float(np.max(iv_mag(genc))))}"
    if kr.unique_zero:
        return dict(verified=True, radius=kr.radius, max_abs_grad=float(np.max(np.abs(g))),
                    text=f"{head}, {width}; {kr.how}: an exact critical point w* lies within {fmt(float(np.max(kr.radius)))} "
                         f"of w, and every decision below is taken on that whole box (so it holds at w*)")
    if certify is not None:
        c = certify(w, s)
        if c is not None:
            return dict(verified=c["verified"], radius=np.asarray(c.get("radius", np.zeros_like(w)), np.float64),
                        max_abs_grad=float(np.max(np.abs(g))), text=f"{head}, {width}; {kr.how}; {c['how']}")
    return dict(verified=None, radius=np.zeros_like(w), max_abs_grad=float(np.max(np.abs(g))),
                text=f"{head}, {width}: consistent with a critical point but not shown to be one ({kr.how})")


def _up(x):
    return float(np.nextafter(float(x), np.inf))


def _down(x):
    return float(np.nextafter(float(x), -np.inf))


def _numeric_conditions(progs, X0, v_iv, vn, vv_b, vv, s0, st, *, rtol, max_pieces):
    """Theorem 1's printed and corrected conditions on a numeric family, rigorously: the sup over zeta
    in [s0 ^ st, s0 v st] of |(d2/ds2 grad J_zeta(w))^T v(w)| over the box X0 of w0 bracketed by interval
    arithmetic (bisected where the bound is largest), each right-hand side enclosed from it, and each
    condition "holds", "not met" or "undecided" against |st - s0|. Returns (bound, how, printed rhs,
    corrected rhs, printed, corrected)."""
    from ._interval import iv_dot, iv_mag, iv_mig

    (vn_lo, vn_hi), (vv_lo, vv_hi) = vn, vv_b
    gap = abs(st - s0)
    gap_hi, gap_lo = (_up(gap), _down(gap)) if gap > 0 else (0.0, 0.0)
    # the sup over zeta of |(d2/ds2 grad J_zeta(w))^T v(w)| for every w in the box: interval arithmetic with zeta
    # ranging over each piece (the natural extension), bisected where the bound is largest
    def upper_on(lo, hi):
        return _up(float(iv_mag(iv_dot(progs.F2_enc(X0, lo, hi), v_iv))))

    def lower_at(zeta):
        return float(iv_mig(iv_dot(progs.F2_enc(X0, zeta), v_iv)))

    thresholds = []
    if gap > 0:
        thresholds = [2 * vn_lo / gap, 2 * vn_hi / gap, 2 * vv_lo / gap, 2 * vv_hi / gap]
    try:
        bound = sup_bound(upper_on, lower_at, min(s0, st), max(s0, st), rtol=rtol, max_pieces=max_pieces,
                          thresholds=[t for t in thresholds if math.isfinite(t)])
    except ValueError as exc:          # an operation without an interval rule
        raise FamilyError(f"cannot bound the sup over zeta rigorously: {exc}") from None
    how = (f"rigorous: interval arithmetic on the traced d2/ds2 grad J over zeta intervals and the box of w0, "
           f"{bound.pieces} piece(s)")

    def rhs(numer_lo, numer_hi, numer, value):     # numer / (sup / 2) with [lo, hi] from the sup's bracket
        lo = math.inf if bound.upper <= 0 else _down(2 * numer_lo / _up(bound.upper))
        hi = math.inf if bound.lower <= 0 else _up(2 * numer_hi / _down(bound.lower))
        return {"value": math.inf if value <= 0 else 2 * numer / value, "lo": lo, "hi": hi}

    prhs = rhs(vn_lo, vn_hi, math.sqrt(vv), bound.lower)
    crhs = rhs(vv_lo, vv_hi, vv, bound.lower)

    def status(r):
        if gap == 0 or r["hi"] == 0:
            return "not met"
        if gap_hi < r["lo"]:
            return "holds"
        if gap_lo > r["hi"]:
            return "not met"
        return "undecided"

    printed, corrected = status(prhs), status(crhs)
    return bound, how, prhs, crhs, printed, corrected


def _wt_row(progs, fam: Family, wtf, st, J_at, J0_box) -> dict:
    """A candidate critical point of J_st given by the family: its certificate and J_st(wt) - J_st(w0)
    enclosed (both boxes the certificates' radii)."""
    from ._interval import iv_mid_rad, iv_sub

    ct = critical_certificate(progs, wtf, st, fam.certify)
    dj = iv_sub(J_at(wtf, ct["radius"]), J0_box)
    dm = float(iv_mid_rad(dj)[0])
    return {"max_abs_grad": ct["max_abs_grad"], "gradient_test": ct["text"],
            "critical": ct["verified"], "consistent_with_critical": ct["verified"] is True,
            "J_st_wt_minus_J_st_w0": _iv(dm, float(dj.lo), float(dj.hi))}


def _theorem1_numeric(fam: Family, s0, st, *, confidence, rtol, max_pieces) -> dict:
    import jax

    from ._interval import IV, iv_dot, iv_mag, iv_mid_rad, iv_mig, iv_sub

    num = _numeric(fam)
    s0, st = float(s0), float(st)
    gap = abs(st - s0)
    with jax.enable_x64(True):
        w0 = np.asarray(fam.w0.ravel(), np.float64)
        progs = _Programs(num, w0, s0)
        try:
            at_w0 = progs.at(_box(w0), st, s0)             # enclosures at the point w0 (float64 rounding only)
        except ValueError as exc:          # an operation without an interval rule
            raise FamilyError(f"cannot enclose the derivatives of J rigorously: {exc}") from None
        except Exception as exc:       # only the user's J runs here
            raise FamilyError(f"J(w, s) cannot be differentiated by JAX at w0: {type(exc).__name__}: {exc}") from None
        gt_, g0, v_bar = (iv_mid_rad(a)[0] for a in at_w0[1:4])
        if not (np.all(np.isfinite(g0)) and np.all(np.isfinite(gt_)) and np.all(np.isfinite(v_bar))):
            raise FamilyError("grad J or d/ds grad J is not finite at w0 (s0 or st)")
        K, P = num.K, w0.size
        try:
            cert0 = critical_certificate(progs, w0, s0, fam.certify)
            X0 = _box(w0, cert0["radius"])
            _, gst_iv, g0_iv, v_iv, curv_iv, _ = progs.at(X0, st, s0, v_bar)
        except ValueError as exc:          # an operation without an interval rule
            raise FamilyError(f"cannot enclose the derivatives of J rigorously: {exc}") from None
        # ||v||^2, C1, the residual grad J_s0^T v (0 at a critical point), C2 -- enclosures over the box of w0
        vv_iv = IV(np.nextafter(float(np.sum(iv_mig(v_iv) ** 2)) * (1 - 4 * P * 2.0 ** -53), -np.inf),
                   np.nextafter(float(np.sum(iv_mag(v_iv) ** 2)) * (1 + 4 * P * 2.0 ** -53), np.inf))
        vv_lo, vv_hi = float(vv_iv.lo), float(vv_iv.hi)
        vn_lo, vn_hi = _down(math.sqrt(max(vv_lo, 0.0))), _up(math.sqrt(vv_hi))
        C1_iv, res0_iv = iv_dot(gst_iv, v_iv), iv_dot(g0_iv, v_iv)
        C2_iv = IV(0.5 * np.asarray(curv_iv.lo), 0.5 * np.asarray(curv_iv.hi))
        mid = lambda a: float(iv_mid_rad(a)[0])
        vv, C1, C2 = float(v_bar @ v_bar), mid(C1_iv), mid(C2_iv)

        bound, how, prhs, crhs, printed, corrected = _numeric_conditions(
            progs, X0, v_iv, (vn_lo, vn_hi), (vv_lo, vv_hi), vv, s0, st, rtol=rtol, max_pieces=max_pieces)
        # descent along v: alpha = C1 / (2 C2) of the quadratic model, J_st enclosed at both points
        alpha_step = C1 / (2 * C2) if C2 > 0 else math.copysign(1e-2, C1) / max(math.sqrt(vv), 1e-30)
        J_at = lambda w, r=None: progs.J_enc(_box(w, r), st)
        d_iv = iv_sub(J_at(w0 - alpha_step * v_bar), J_at(w0))
        descent = True if float(d_iv.hi) < 0 else None            # a difference within rounding decides nothing
        # the conclusion on the known critical points of J_st
        J0_box = J_at(w0, cert0["radius"])
        wt_rows = [_wt_row(progs, fam, np.asarray(wt.ravel(), np.float64), st, J_at, J0_box) for wt in fam.wt or []]
    refuting = [r for r in wt_rows if r["critical"] is True and r["J_st_wt_minus_J_st_w0"]["lo"] >= 0]
    conclusion = decide(fails=bool(refuting))
    res0_mag = float(iv_mag(res0_iv))
    hyps = [_hyp("s_positive", "s0, st in (0, inf)", s0 > 0 and st > 0, f"s0 = {s0:g}, st = {st:g}"),
            _hyp("st_ne_s0", "0 < |st - s0| (ass:Laplacian-properties)", gap > 0, f"|st - s0| = {fmt(gap)}"),
            _hyp("w0_critical", "w0 in {grad J_s0 = 0} (ass:Nonempty-minimizer-sets)", cert0["verified"],
                 f"{cert0['text']}; |grad J_s0^T v| <= {fmt(res0_mag)} on the box"),
            _hyp("printed_condition", "ass:Laplacian-properties as printed", printed == "holds",
                 f"{printed}: |st - s0| = {fmt(gap)} vs printed rhs in [{fmt(prhs['lo'])}, {fmt(prhs['hi'])}]")]
    if fam.wt:
        n_ok = sum(r["critical"] is True for r in wt_rows)
        hyps.append(_hyp("wt_exists", "{grad J_st = 0} nonempty (ass:Nonempty-minimizer-sets)", True if n_ok else None,
                         f"{len(wt_rows)} candidate critical point(s) of J_st given by the family, {n_ok} shown "
                         f"critical: " + "; ".join(r["gradient_test"] for r in wt_rows)))
    I = lambda a: _iv(mid(a), float(a.lo), float(a.hi))
    res = {
        "family": "numeric", "name": fam.name, "s0": s0, "st": st, "gap": gap, "confidence": confidence,
        "exact": True, "K": K, "P": P,
        "v_norm2": _iv(vv, vv_lo, vv_hi), "v_norm": math.sqrt(vv), "v_bar": v_bar.tolist(),
        "sup_abs_d2_dot_v": {"value": bound.lower, "lo": bound.lower, "hi": bound.upper, "how": how},
        "printed_rhs": prhs, "corrected_rhs": crhs,
        "printed_condition": printed, "corrected_condition": corrected,
        "C1": I(C1_iv), "C1_proof": I(iv_sub(C1_iv, res0_iv)), "critical_residual_grad_s0_dot_v": I(res0_iv),
        "C2_at_alpha0": I(C2_iv), "alpha": float(alpha_step),
        "J_st_difference": I(d_iv), "w0_certificate": {"verified": cert0["verified"], "text": cert0["text"],
                                                       "radius": float(np.max(cert0["radius"]))},
        "descent": {"exists": descent, "detail": f"J_st(w0 - alpha v) - J_st(w0) in [{fmt(float(d_iv.lo))}, "
                                                 f"{fmt(float(d_iv.hi))}] at alpha = C1/(2 C2) = {fmt(alpha_step)}"},
        "wt": wt_rows, "hypotheses": hyps, "conclusion": conclusion,
    }
    wt_text = "; ".join(f"candidate critical point {i + 1} of J_st: {r['gradient_test']} ("
                        f"{'critical' if r['critical'] else 'NOT critical: not used' if r['critical'] is False else 'not shown critical: not used'}), "
                        f"J_st(w_t) - J_st(w0) in [{fmt(r['J_st_wt_minus_J_st_w0']['lo'])}, "
                        f"{fmt(r['J_st_wt_minus_J_st_w0']['hi'])}]" for i, r in enumerate(wt_rows))
    res["evidence"] = _evidence(res, extra=(wt_text + "; " if wt_text else "")
                                + f"sup over zeta {how}; the objective is the mean of the K = {K} per-sample value(s), "
                                  f"computed exactly up to float64 rounding, which every interval encloses"
                                + ("" if wt_rows else "; no critical point of J_st known to the family: the printed "
                                   "conclusion (every critical point) cannot be decided numerically"))
    return res


def render(res: dict) -> str:
    """Human-readable lines of a :func:`theorem1` result."""
    iv = lambda d: (fmt(d["value"]) if d["lo"] == d["hi"] else f"{fmt(d['value'])} [{fmt(d['lo'])}, {fmt(d['hi'])}]")
    sup = res.get("sup_abs_d2_dot_v")
    lines = [f"Theorem 1 on {res['name']} ({res['family']}) at s0 = {res['s0']:g}, st = {res['st']:g}",
             f"  ||v||^2 = {iv(res['v_norm2'])},  v = d/ds grad J_s0(w0)",
             f"  sup_zeta |(d2/ds2 grad J_zeta(w0))^T v| = {iv(sup) if sup else 'n/a'}"
             + (f"  ({sup['how']})" if sup else ""),
             f"  printed rhs   {iv(res['printed_rhs'])}  -> |st - s0| = {fmt(res['gap'])}: {res['printed_condition']}",
             f"  corrected rhs {iv(res['corrected_rhs'])}  -> {res['corrected_condition']}",
             f"  C1 = {iv(res['C1'])}",
             f"  conclusion: {res['conclusion']}",
             "  hypotheses: " + "; ".join(f"{h['name']}: {h['verified']}" for h in res["hypotheses"]),
             "", res["evidence"]]
    return "\n".join(lines)
