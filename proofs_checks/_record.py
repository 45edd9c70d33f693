"""The verdict record of reference §4 and the rules that turn numbers into verdicts.

Every verdict is computed from a comparison made on the current run: a symbolic
difference that is or is not zero, or a statistic against a stated critical value.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from scipy import stats

#: the three verdicts of reference §4
VERDICTS = ("holds", "fails", "inconclusive")

#: family-wise error of one `gift check` run: the probability that any numerical test of any
#: check decides wrongly is at most FAMILY_ALPHA (Bonferroni)
FAMILY_ALPHA = 1e-3
#: the family-wise error is split into SHARES equal shares, one per registered check (the
#: registry holds at most SHARES checks); a check splits its share over its own tests
SHARES = 24
ALPHA_CHECK = FAMILY_ALPHA / SHARES

#: default two-sided confidence of a single numerical test outside a check (z about 4.42)
CONFIDENCE = 1.0 - 1e-5


class Level(NamedTuple):
    """The error level of each of ``tests`` numerical tests of one check (its share of the
    family-wise level, split by Bonferroni)."""

    tests: int

    @property
    def alpha(self) -> float:
        """Two-sided error of each test."""
        return ALPHA_CHECK / self.tests

    @property
    def confidence(self) -> float:
        return 1.0 - self.alpha

    @property
    def z2(self) -> float:
        """Two-sided critical value."""
        return float(stats.norm.isf(self.alpha / 2))

    @property
    def z1(self) -> float:
        """One-sided critical value."""
        return float(stats.norm.isf(self.alpha))

    def text(self) -> str:
        return (f"level: family-wise error {FAMILY_ALPHA:g} over the whole run (Bonferroni, {ALPHA_CHECK:g} per "
                f"check), split over {self.tests} test(s) here: alpha = {self.alpha:.3g} each (two-sided |z| > "
                f"{self.z2:.2f}, one-sided z > {self.z1:.2f})")


def level(tests: int = 1) -> Level:
    """This check's per-test level when it runs ``tests`` numerical tests."""
    return Level(max(int(tests), 1))


def z_crit(confidence: float = CONFIDENCE) -> float:
    """Two-sided normal critical value for ``confidence``."""
    return float(stats.norm.isf((1.0 - confidence) / 2.0))


def record(id: str, claim: str, verdict: str, evidence: str, correction: str | None = None,
           counterexample: Any = None, hypotheses: list | None = None) -> dict:
    """One reference §4 record ``{id, claim, verdict, evidence, correction, counterexample}``
    plus ``hypotheses``: the statement's hypotheses, each ``{"name", "statement", "verified",
    "detail", "needed_for_refutation", "assumed"}`` on the check's instance(s) (``verified``
    True/False computed on the instance, or None when undecided or assumed), and the findings an
    out-of-hypothesis instance supports.

    A "fails" verdict must carry a counterexample or a computed difference (in
    ``counterexample``). It stands only when every hypothesis it rests on
    (``needed_for_refutation``) is verified -- True, computed, not None and not assumed; otherwise
    the record says "inconclusive" and its evidence names the hypotheses that are false (the
    instance is outside the statement) or not verified (undecided or assumed), so no check can
    emit a refutation that rests on an unverified hypothesis.
    """
    if verdict not in VERDICTS:
        raise ValueError(f"verdict must be one of {VERDICTS}, got {verdict!r}")
    if verdict == "fails" and counterexample is None:
        raise ValueError(f"{id}: a 'fails' verdict needs a counterexample or a computed difference")
    hypotheses = [dict(h, assumed=bool(h.get("assumed", False))) for h in (hypotheses or [])]
    for h in hypotheses:
        if h["assumed"] and h.get("verified") is not None:
            raise ValueError(f"{id}: hypothesis {h['name']!r} is assumed, so its 'verified' must be None")
    needed = [h for h in hypotheses if h.get("needed_for_refutation", True)]
    if verdict == "fails":
        false = [h["name"] for h in needed if h.get("verified") is False]
        unverified = [h["name"] for h in needed if h.get("verified") is None]
        if false or unverified:
            verdict = VERDICTS[2]
            why = []
            if false:
                why.append(f"outside the statement's hypotheses: {', '.join(false)} computed false on its instance")
            if unverified:
                why.append(f"hypotheses not verified on its instance (undecided or assumed): {', '.join(unverified)}")
            evidence = (f"{evidence.rstrip()} [A refutation was computed but is not reported as one: "
                        f"{'; '.join(why)}.]")
        elif needed:
            evidence = (f"{evidence.rstrip()} [The refutation is inside the statement's hypotheses: "
                        f"{', '.join(h['name'] for h in needed)} verified on its instance(s).]")
    return {"id": id, "claim": claim, "verdict": verdict, "evidence": evidence,
            "correction": correction, "counterexample": counterexample, "hypotheses": hypotheses}


def hypothesis(name: str, statement: str, verified, detail: str = "", *, needed_for_refutation: bool = True) -> dict:
    """One hypothesis of a statement and whether it was verified on the check's instance:
    ``verified`` is the outcome of a computation on the instance (True, False) or None when the
    computation could not decide.

    ``needed_for_refutation=False`` marks an instance reported only as a finding outside the
    statement (it does not block a refutation made on another instance)."""
    return {"name": name, "statement": statement, "verified": None if verified is None else bool(verified),
            "detail": detail, "needed_for_refutation": needed_for_refutation, "assumed": False}


def assumed(name: str, statement: str, why: str, *, needed_for_refutation: bool = True) -> dict:
    """A hypothesis taken without computation on the instance: ``verified`` None, ``assumed`` True,
    its detail starts with "assumed". It can never carry a refutation (see :func:`record`)."""
    return {"name": name, "statement": statement, "verified": None, "detail": f"assumed (not computed): {why}",
            "needed_for_refutation": needed_for_refutation, "assumed": True}


def hypothesis_counts(rec) -> dict:
    """Counts of a record's hypotheses: verified (computed True), false (computed False),
    undecided (computed, None) and assumed."""
    hs = rec.get("hypotheses") or []
    return {"verified": sum(h.get("verified") is True for h in hs),
            "false": sum(h.get("verified") is False for h in hs),
            "undecided": sum(h.get("verified") is None and not h.get("assumed") for h in hs),
            "assumed": sum(bool(h.get("assumed")) for h in hs), "total": len(hs)}


def decide(*, fails: bool = False, holds: bool = False) -> str:
    """The verdict from computed conditions: "fails" when the refutation condition is met (it
    wins), else "holds" when the confirmation condition is met, else "inconclusive"."""
    if bool(fails):
        return VERDICTS[1]
    return VERDICTS[0] if bool(holds) else VERDICTS[2]


def symbolic_verdict(is_zero: bool) -> str:
    """A printed identity holds iff the symbolic difference simplifies to zero."""
    return VERDICTS[0] if bool(is_zero) else VERDICTS[1]


def equality_verdict(diff: float, se: float, scale: float, *, confidence: float = CONFIDENCE,
                     rel_tol: float = 0.1) -> tuple[str, float]:
    """Test ``E[diff] == 0`` from an estimate with standard error ``se``.

    "fails" when |diff| > z_crit se (the difference is significant at ``confidence``);
    "holds" when it is not and the test had the power to see a relative departure of
    ``rel_tol`` of ``scale`` (z_crit se < rel_tol |scale|); otherwise "inconclusive".

    Returns
    -------
    (verdict, z) with z = diff / se
    """
    zc = z_crit(confidence)
    if not (math.isfinite(float(diff)) and math.isfinite(float(se))):
        return VERDICTS[2], math.nan
    z = float(diff) / float(se) if se > 0 else (math.inf if diff != 0 else 0.0)
    if abs(z) > zc:
        return VERDICTS[1], z
    if zc * float(se) < rel_tol * abs(float(scale)):
        return VERDICTS[0], z
    return VERDICTS[2], z


def sign_verdict(value: float, se: float, want: str, *, confidence: float = CONFIDENCE) -> tuple[str, float]:
    """Test a one-sided claim ``value < 0`` (``want="negative"``) or ``> 0``.

    "holds" when the estimate is beyond the one-sided critical value in the wanted
    direction, "fails" when it is significantly on the other side, else "inconclusive".
    """
    zc = float(stats.norm.isf(1.0 - confidence))
    if not (math.isfinite(float(value)) and math.isfinite(float(se))):
        return VERDICTS[2], math.nan
    z = float(value) / float(se) if se > 0 else math.copysign(math.inf, value) if value != 0 else 0.0
    good = -z if want == "negative" else z
    if good > zc:
        return VERDICTS[0], z
    if good < -zc:
        return VERDICTS[1], z
    return VERDICTS[2], z


def combine(*verdicts: str) -> str:
    """All parts of a claim: "fails" if any part fails, "holds" if all hold."""
    if VERDICTS[1] in verdicts:
        return VERDICTS[1]
    if all(v == VERDICTS[0] for v in verdicts):
        return VERDICTS[0]
    return VERDICTS[2]


def fmt(x: float, nd: int = 3) -> str:
    """Short number formatting for evidence lines."""
    x = float(x)
    if x == 0 or not math.isfinite(x):
        return str(x)
    return f"{x:.{nd}g}"
