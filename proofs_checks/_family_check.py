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

Where each decision lives: the family and its loading in :mod:`._family`; the exact path in
:mod:`._family_sympy` (on the arithmetic of :mod:`._exact`); the numeric path in
:mod:`._family_numeric`; the hypothesis rows and the evidence sentence both build in
:mod:`._family_result`; this module dispatches and writes the result out (:func:`contract_json`,
:func:`render`).
"""

from __future__ import annotations

from ._family import Family
from ._family_numeric import _theorem1_numeric
from ._family_result import inside_hypotheses
from ._family_sympy import _theorem1_sympy
from ._record import fmt


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
