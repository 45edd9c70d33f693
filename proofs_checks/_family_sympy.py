"""Theorem 1 on a sympy family, exactly: derivatives, ||v||, C1, the sup over zeta (exact critical
points, or a rigorous mpmath interval bound when sympy cannot list them), the printed and
corrected conditions and the critical points of J_st (reference §5b).
"""

from __future__ import annotations

import math

import numpy as np

from ._exact import _critical_points, _exact, _f, _line_descent, _sign, _zero_proven, exact_sup_abs
from ._family import Family, FamilyError
from ._family_result import _evidence, _hyp, _iv
from ._interval import float_up, sup_bound, sympy_enclosure
from ._record import decide, fmt


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
