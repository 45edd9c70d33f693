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
  (shape (K,), the objective being their mean) and an array ``w0``. Per-sample values give
  confidence intervals (U-statistics over the K samples, simultaneous at ``confidence`` by
  Bonferroni); the sup over zeta is bounded rigorously by interval arithmetic on the traced
  computation (:mod:`proofs_checks._interval`, centred form with adaptive bisection). An
  optional ``wt`` (an array or a list of arrays) names critical points of J_st that the
  family knows (e.g. analytically); the conclusion is then tested on them.

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

from ._interval import float_up, jaxpr_enclosure, sup_bound, sympy_enclosure
from ._record import decide, fmt

#: what a family file must define (reference §5b)
FAMILY_NAMES = ("s", "w", "J", "w0")


class Family(NamedTuple):
    """A J_s family. ``kind`` is "sympy" or "numeric"; ``wt`` optional critical points of J_st."""

    kind: str
    J: Any
    w0: Any
    s: Any = None
    w: tuple = ()
    wt: Any = None
    name: str = "family"


class FamilyError(ValueError):
    """A family that breaks the contract of reference §5b (one line, names the rule)."""

    def __init__(self, message):
        super().__init__(" ".join(str(message).split()))      # one line, whatever the cause's text


# --------------------------------------------------------------------------------------
# building and loading families
# --------------------------------------------------------------------------------------
def family(J, w0, *, s=None, w=None, wt=None, name: str = "family") -> Family:
    """A :class:`Family` from sympy objects (``s``, ``w``, expression ``J``) or from a
    JAX-differentiable ``J(w, s)`` and an array ``w0``."""
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
        return Family("numeric", J, w0a, None, (), wts, name)
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
                      name=os.path.basename(path))
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
    critical0 = all(_sign(x) == 0 for x in g0)
    hint = ""
    big = max(abs(float(sp.N(x, 30))) for x in g0) if g0 else 0.0
    if not critical0 and big < 1e-8:
        # a decimal w0 (a float solution) is a critical point only to a float's precision: the exact
        # check needs it exact, and says so rather than a bare "not critical"
        hint = (f"; |grad J_s0(w0)| = {big:.2g}: zero to a float's precision, not exactly -- a decimal w0 is "
                f"rounded; give it exactly (sp.Rational, sp.sqrt, or a root from sp.solve(sp.diff(J, w).subs(s, "
                f"s0), w)) for the exact check, or write the family as a numeric J(w, s), which is checked with "
                f"confidence intervals")
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
    bad = [i for i, sg in enumerate(signs) if sg >= 0]
    hyps.append(_hyp("wt_exists", "{grad J_st = 0} nonempty (ass:Nonempty-minimizer-sets)",
                     bool(pts) if (pts or complete) else None, how_pts))
    conclusion = decide(fails=bool(bad), holds=bool(pts) and complete)
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
# numeric families (JAX), with confidence intervals
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


#: rounding allowance of a per-sample gradient mean (K > 1): 2^-40 times the mean |g_i| over the
#: samples (float64 sums of K terms err by far less), so a coordinate whose samples all agree
#: (standard error 0) is not "infinitely significant" for a residual at rounding level
_ROUNDING_REL = 2.0 ** -40


def gradient_zero_test(f, g, w, s, alpha: float) -> dict:
    """Is the whole gradient grad J_s(w) = 0, within its own numerical error?

    ``g`` (K, P) are the per-sample gradients at ``w`` (the objective is their mean). With K > 1
    every coordinate gets a two-sided z-test at alpha / P (Bonferroni: the whole gradient at
    level ``alpha``), its mean counted as nonzero only beyond z se + a rounding allowance.
    With K = 1 (a deterministic family) the gradient is enclosed rigorously by interval
    arithmetic on the traced computation over the rounding box of w (each coordinate within
    one relative unit roundoff 2^-53, every operation rounded outwards): a coordinate is
    nonzero when its enclosure excludes 0 -- then no point of float64 precision around w is
    critical.

    Returns
    -------
    dict(nonzero: bool -- some coordinate is nonzero at the level, consistent: bool,
    max_abs: float, n_nonzero: int, tolerance: (P,) the allowance of each coordinate, text)
    """
    import jax
    import jax.numpy as jnp
    from scipy import stats

    K, P = g.shape
    gm = g.mean(0)
    if K > 1:
        se = g.std(0, ddof=1) / math.sqrt(K)
        zc = float(stats.norm.isf(alpha / (2 * P)))
        tol = _ROUNDING_REL * np.abs(g).mean(0)
        excess = np.maximum(np.abs(gm) - tol, 0.0)
        nz = excess > zc * se
        z = np.where(se > 0, excess / np.where(se > 0, se, 1.0), np.where(excess > 0, np.inf, 0.0))
        text = (f"whole gradient, {P} coordinate(s): max |z| = {fmt(float(np.max(z)))} against z = {zc:.2f} "
                f"(two-sided, Bonferroni over the coordinates at {alpha:.2g}; rounding allowance 2^-40 mean|g_i|): "
                f"{int(nz.sum())} coordinate(s) significantly nonzero")
        tolerance = zc * se + tol
    else:
        from ._interval import jaxpr_enclosure

        gfun = jax.jacfwd(lambda wf, s_: f(wf, s_), argnums=0)
        fn = lambda t: jnp.mean(gfun(jnp.asarray(w, jnp.float64) * (1 + t), jnp.float64(s)), axis=0)
        try:
            enc = jaxpr_enclosure(fn, 0.0)(-2.0 ** -53, 2.0 ** -53)
        except ValueError as exc:            # an operation without an interval rule
            raise FamilyError(f"cannot enclose grad J rigorously to test criticality: {exc}") from None
        lo, hi = np.asarray(enc.lo).reshape(P), np.asarray(enc.hi).reshape(P)
        nz = (lo > 0) | (hi < 0)
        tolerance = np.maximum(np.abs(lo), np.abs(hi))
        text = (f"whole gradient, {P} coordinate(s), float64 with a rigorous enclosure over the rounding box of the "
                f"point (interval arithmetic, outward rounding; half-width up to {fmt(float(np.max(hi - lo) / 2))}): "
                f"{int(nz.sum())} coordinate(s) whose enclosure excludes 0")
    return {"nonzero": bool(np.any(nz)), "consistent": not bool(np.any(nz)), "max_abs": float(np.max(np.abs(gm))),
            "n_nonzero": int(nz.sum()), "tolerance": tolerance, "text": text}


def _ustat(a, b):
    """Unbiased E[a]^T E[b] from per-sample rows a, b (K, P) of the same samples, with its
    standard error (U-statistic over pairs i != j; Hoeffding projection a_i.b_bar + a_bar.b_i)."""
    K = a.shape[0]
    if K == 1:
        return float(a[0] @ b[0]), 0.0
    ab, bb = a.mean(0), b.mean(0)
    T = float((K * K * (ab @ bb) - np.sum(a * b)) / (K * (K - 1)))
    psi = a @ bb + b @ ab
    return T, float(psi.std(ddof=1) / math.sqrt(K))


def _theorem1_numeric(fam: Family, s0, st, *, confidence, rtol, max_pieces) -> dict:
    import jax
    import jax.numpy as jnp
    from scipy import stats

    num = _numeric(fam)
    s0, st = float(s0), float(st)
    # simultaneous intervals (Bonferroni), each two-sided at alpha / n_int: ||v||^2, C1, the criticality
    # residual, C1_proof, C2, the descent difference, the whole gradient at w0, two for the sup over zeta (its
    # upper bound, one-sided at the maximiser; its lower bound, one-sided at three fixed points), and per known
    # critical point of
    # J_st its gradient test (split over the coordinates) and J_st(w_t) - J_st(w0)
    n_int = 9 + 2 * len(fam.wt or [])
    alpha = 1.0 - confidence
    z = float(stats.norm.isf(alpha / (2 * n_int)))
    f = num.per_sample
    with jax.enable_x64(True):
        w0 = jnp.asarray(fam.w0.ravel(), jnp.float64)
        jac_w = jax.jit(jax.jacfwd(f, argnums=0))
        ds = jax.jit(jax.jacfwd(jax.jacfwd(f, argnums=0), argnums=1))

        def dk(k):
            def g(wf, zeta):
                fn = lambda s_: f(wf, s_)
                for _ in range(k):
                    fn = (lambda q: (lambda s_: jax.jvp(q, (s_,), (jnp.ones((), jnp.float64),))[1]))(fn)
                return fn(zeta)
            return g

        F2 = jax.jit(lambda zeta: jax.jacfwd(dk(2), argnums=0)(w0, zeta))          # (K, P)
        F3 = lambda zeta: jax.jacfwd(dk(3), argnums=0)(w0, zeta)
        try:
            g0 = np.asarray(jac_w(w0, jnp.float64(s0)))
            gt_ = np.asarray(jac_w(w0, jnp.float64(st)))
            vs = np.asarray(ds(w0, jnp.float64(s0)))
        except Exception as exc:       # only the user's J runs here
            raise FamilyError(f"J(w, s) cannot be differentiated by JAX at w0: {type(exc).__name__}: {exc}") from None
        if not (np.all(np.isfinite(g0)) and np.all(np.isfinite(gt_)) and np.all(np.isfinite(vs))):
            raise FamilyError("grad J or d/ds grad J is not finite at w0 (s0 or st)")
        K, P = vs.shape
        v_bar = vs.mean(0)
        vv, vv_se = _ustat(vs, vs)
        C1, C1_se = _ustat(gt_, vs)
        res0, res0_se = _ustat(g0, vs)
        C1p, C1p_se = _ustat(gt_ - g0, vs)
        c = K * v_bar[None, :] - vs                       # T(zeta) = sum_i F_i . c_i / (K (K - 1))

        def T_and_se_point(zeta):
            Fz = np.asarray(F2(jnp.float64(zeta)))
            return _ustat(Fz, vs)

        enc3 = jaxpr_enclosure(F3, 0.5 * (s0 + st))

        def upper_on(lo, hi):
            m, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
            Fm = np.asarray(F2(jnp.float64(m)))
            d = enc3(lo, hi)
            rad = np.maximum(np.abs(d.lo), np.abs(d.hi)) * r * (1 + 1e-12) + 1e-300   # |F_i(zeta) - F_i(m)| <= rad
            if K == 1:
                Tm = float(Fm[0] @ vs[0])
                return abs(Tm) + float(rad[0] @ np.abs(vs[0])) * (1 + 1e-12)
            Tm = float(np.sum(Fm * c) / (K * (K - 1)))
            Trad = float(np.sum(rad * np.abs(c)) / (K * (K - 1)))
            # se: psi_i = F_i . v_bar + F_bar . v_i, each within its radius
            Fbar, Fbar_rad = Fm.mean(0), rad.mean(0)
            psi_m = Fm @ v_bar + vs @ Fbar
            psi_rad = rad @ np.abs(v_bar) + np.abs(vs) @ Fbar_rad
            mean_lo, mean_hi = (psi_m - psi_rad).mean(), (psi_m + psi_rad).mean()
            dev = np.maximum(np.abs(psi_m + psi_rad - mean_lo), np.abs(psi_m - psi_rad - mean_hi))
            se_hi = math.sqrt(float(np.sum(dev ** 2)) / (K - 1) / K)
            return (abs(Tm) + Trad) * (1 + 1e-12) + z * se_hi

        def lower_at(zeta):          # (lower confidence limit, upper confidence limit) at zeta
            T, se = T_and_se_point(zeta)
            return max(abs(T) - z * se, 0.0), abs(T) + z * se

        gap = abs(st - s0)
        vv_lo, vv_hi = max(vv - z * vv_se, 0.0), vv + z * vv_se
        thresholds = []
        if gap > 0:
            thresholds = [2 * math.sqrt(vv_lo) / gap, 2 * math.sqrt(vv_hi) / gap, 2 * vv_lo / gap, 2 * vv_hi / gap]
        try:
            bound = sup_bound(upper_on, lower_at, min(s0, st), max(s0, st), rtol=rtol, max_pieces=max_pieces,
                              thresholds=[t for t in thresholds if math.isfinite(t)], fixed_lower=K > 1)
            how = (f"rigorous in zeta: interval arithmetic on the traced d3/ds3 grad J (centred form), "
                   f"{bound.pieces} piece(s); per-zeta confidence 1 - {alpha / n_int:.2g}")
        except ValueError as exc:          # an operation without an interval rule
            raise FamilyError(f"cannot bound the sup over zeta rigorously: {exc}") from None
        est_pts = [T_and_se_point(t) for t in (min(s0, st), 0.5 * (s0 + st), max(s0, st))]
        sup_est = max(abs(t) for t, _ in est_pts)

        # the printed and corrected right-hand sides with their intervals
        def rhs(numv, M):
            return math.inf if M <= 0 else numv / (0.5 * M)

        vn, vn_lo, vn_hi = math.sqrt(max(vv, 0)), math.sqrt(vv_lo), math.sqrt(vv_hi)
        prhs = {"value": rhs(vn, sup_est), "lo": rhs(vn_lo, bound.upper), "hi": rhs(vn_hi, bound.lower)}
        crhs = {"value": rhs(vv, sup_est), "lo": rhs(vv_lo, bound.upper), "hi": rhs(vv_hi, bound.lower)}

        def status(r):
            if gap == 0 or r["hi"] == 0:
                return "not met"
            if gap < r["lo"]:
                return "holds"
            if gap >= r["hi"]:
                return "not met"
            return "undecided"

        printed, corrected = status(prhs), status(crhs)
        # w0 critical: the whole gradient grad J_s0(w0) = 0 within its own numerical error (a z-test per
        # coordinate, or a rigorous enclosure for a deterministic family). The proof uses it through
        # r = grad J_s0(w0)^T v (C1 = r + C1_proof, C1_proof = (grad J_st - grad J_s0)(w0)^T v); a trained w0 is
        # critical only approximately, so with K > 1 "verified" also needs the power to matter: the upper
        # confidence limit of |r| below the lower one of |C1_proof| (r cannot change the sign of C1).
        gz = gradient_zero_test(f, g0, np.asarray(w0), s0, alpha / n_int)
        g0_bar = g0.mean(0)
        res_hi = abs(res0) + z * res0_se
        c1p_lo = abs(C1p) - z * C1p_se
        if K > 1:
            power = res_hi < c1p_lo
            crit_ok = False if (gz["nonzero"] or abs(res0) > z * res0_se) else (True if power else None)
            crit_text = (f"{gz['text']}; grad J_s0(w0)^T v = {fmt(res0)} +- {fmt(res0_se)} (|.| <= {fmt(res_hi)} at the "
                         f"confidence) against |C1_proof| = |(grad J_st - grad J_s0)(w0)^T v| >= {fmt(max(c1p_lo, 0.0))}: "
                         + ("the residual cannot change the sign of C1" if power else
                            "the residual may change the sign of C1 (no power)"))
        else:
            crit_ok = gz["consistent"]
            crit_text = f"{gz['text']}; grad J_s0(w0)^T v = {fmt(res0)}"
        # descent along v: alpha = C1 / (2 C2) of the quadratic model, paired per-sample test
        hvp = jax.jit(lambda wf, t: jax.jvp(lambda q: jax.jacfwd(f)(q, jnp.float64(st)), (wf,), (t,))[1])
        H = np.asarray(hvp(w0, jnp.asarray(v_bar)))                          # (K, P)
        C2, C2_se = _ustat(H, vs)
        C2 *= 0.5
        alpha_step = C1 / (2 * C2) if C2 > 0 else math.copysign(1e-2, C1) / max(vn, 1e-30)
        fj = jax.jit(f)
        diff = np.asarray(fj(w0 - alpha_step * jnp.asarray(v_bar), jnp.float64(st))) - np.asarray(
            fj(w0, jnp.float64(st)))
        d_mean = float(diff.mean())
        d_se = float(diff.std(ddof=1) / math.sqrt(K)) if K > 1 else 0.0
        descent = (d_mean + z * d_se < 0) if K > 1 else d_mean < 0
        descent = True if descent else None                  # a non-significant difference decides nothing
        # the conclusion on the known critical points of J_st
        wt_rows = []
        for wt in fam.wt or []:
            wtf = jnp.asarray(wt.ravel(), jnp.float64)
            gt_wt = np.asarray(jac_w(wtf, jnp.float64(st)))
            gzt = gradient_zero_test(f, gt_wt, np.asarray(wtf), st, alpha / n_int)
            dj = np.asarray(fj(wtf, jnp.float64(st))) - np.asarray(fj(w0, jnp.float64(st)))
            dm, dse = float(dj.mean()), (float(dj.std(ddof=1) / math.sqrt(K)) if K > 1 else 0.0)
            wt_rows.append({"max_abs_grad": gzt["max_abs"], "gradient_test": gzt["text"],
                            "consistent_with_critical": gzt["consistent"],
                            "J_st_wt_minus_J_st_w0": _iv(dm, dm - z * dse, dm + z * dse)})
    refuting = [r for r in wt_rows if r["consistent_with_critical"] and r["J_st_wt_minus_J_st_w0"]["lo"] >= 0]
    conclusion = decide(fails=bool(refuting))
    hyps = [_hyp("s_positive", "s0, st in (0, inf)", s0 > 0 and st > 0, f"s0 = {s0:g}, st = {st:g}"),
            _hyp("st_ne_s0", "0 < |st - s0| (ass:Laplacian-properties)", gap > 0, f"|st - s0| = {fmt(gap)}"),
            _hyp("w0_critical", "w0 in {grad J_s0 = 0} (ass:Nonempty-minimizer-sets)", crit_ok,
                 f"{crit_text}; max |grad J_s0(w0)| = {fmt(float(np.max(np.abs(g0_bar))))}"),
            _hyp("printed_condition", "ass:Laplacian-properties as printed", printed == "holds",
                 f"{printed}: |st - s0| = {fmt(gap)} vs printed rhs in [{fmt(prhs['lo'])}, {fmt(prhs['hi'])}]")]
    if fam.wt:
        hyps.append(_hyp("wt_exists", "{grad J_st = 0} nonempty (ass:Nonempty-minimizer-sets)",
                         any(r["consistent_with_critical"] for r in wt_rows),
                         f"{len(wt_rows)} critical point(s) of J_st given by the family (their criticality is the "
                         f"family's statement, e.g. analytic; the whole-gradient test can only fail to contradict "
                         f"it), {sum(r['consistent_with_critical'] for r in wt_rows)} not contradicted: "
                         + "; ".join(r["gradient_test"] for r in wt_rows)))
    I = lambda m, se: _iv(m, m - z * se, m + z * se)
    res = {
        "family": "numeric", "name": fam.name, "s0": s0, "st": st, "gap": gap, "confidence": confidence,
        "exact": K == 1, "K": K, "P": P, "z": z,
        "v_norm2": I(vv, vv_se), "v_norm": vn, "v_bar": v_bar.tolist(),
        "sup_abs_d2_dot_v": {"value": sup_est, "lo": bound.lower, "hi": bound.upper, "how": how},
        "printed_rhs": prhs, "corrected_rhs": crhs,
        "printed_condition": printed, "corrected_condition": corrected,
        "C1": I(C1, C1_se), "C1_proof": I(C1p, C1p_se), "critical_residual_grad_s0_dot_v": I(res0, res0_se),
        "C2_at_alpha0": I(C2, 0.5 * C2_se), "alpha": float(alpha_step),
        "J_st_difference": I(d_mean, d_se),
        "descent": {"exists": descent, "detail": f"J_st(w0 - alpha v) - J_st(w0) = {fmt(d_mean)} +- "
                                                        f"{fmt(d_se)} at alpha = C1/(2 C2) = {fmt(alpha_step)} "
                                                        f"(paired over the same samples)"},
        "wt": wt_rows, "hypotheses": hyps, "conclusion": conclusion,
    }
    wt_text = "; ".join(f"known critical point {i + 1} of J_st (critical by the family's statement): "
                        f"{r['gradient_test']} ("
                        f"{'not contradicted' if r['consistent_with_critical'] else 'CONTRADICTED: not used'}), "
                        f"J_st(w_t) - J_st(w0) = "
                        f"{fmt(r['J_st_wt_minus_J_st_w0']['value'])} [{fmt(r['J_st_wt_minus_J_st_w0']['lo'])}, "
                        f"{fmt(r['J_st_wt_minus_J_st_w0']['hi'])}]" for i, r in enumerate(wt_rows))
    res["evidence"] = _evidence(res, extra=(wt_text + "; " if wt_text else "")
                                + f"sup over zeta {how}; intervals from K = {K} samples (z = {z:.2f})"
                                + ("" if wt_rows else "; no critical point of J_st known to the family: the "
                                   "printed conclusion (every critical point) cannot be decided numerically"))
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
