"""The parts of a Theorem 1 result that both paths build (:mod:`._family_sympy`,
:mod:`._family_numeric`): a hypothesis row, an interval {value, lo, hi}, whether the instance is
inside the theorem's hypotheses, and the evidence sentence.
"""

from __future__ import annotations

from ._record import fmt, hypothesis


def inside_hypotheses(res: dict):
    """True when every hypothesis of Theorem 1 is verified on the instance, False when one is
    computed false (the instance lies outside the theorem), None when one is undecided."""
    vs = [h["verified"] for h in res["hypotheses"] if h.get("needed_for_refutation", True)]
    return False if any(v is False for v in vs) else (True if all(v is True for v in vs) else None)


def _hyp(name, statement, verified, detail):
    return hypothesis(name, statement, verified, str(detail))


def _iv(value, lo=None, hi=None):
    value = float(value)
    return {"value": value, "lo": value if lo is None else float(lo), "hi": value if hi is None else float(hi)}


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
