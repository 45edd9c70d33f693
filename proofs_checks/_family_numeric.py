"""Theorem 1 on a numeric (JAX) family: the objective is the finite mean of the K per-sample values,
so its derivatives are computed, not estimated; every number that decides anything is enclosed by
float64 interval arithmetic on the traced computation (:mod:`._interval`), w0 and each candidate
critical point of J_st are certified by Krawczyk's test (or the family's ``certify``), and the sup
over zeta is bracketed by bisection (reference §5b).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from ._family import Family, FamilyError
from ._family_result import _evidence, _hyp, _iv
from ._interval import sup_bound
from ._record import decide, fmt


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
