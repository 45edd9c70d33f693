"""The verdict record of CONTRACTS §4 and the rules that turn numbers into verdicts.

Every verdict is computed from a comparison made on the current run: a symbolic
difference that is or is not zero, or a statistic against a stated critical value.
"""

from __future__ import annotations

import math
from typing import Any

from scipy import stats

#: the three verdicts of CONTRACTS §4
VERDICTS = ("holds", "fails", "inconclusive")

#: default two-sided confidence of every numerical test (z about 4.42)
CONFIDENCE = 1.0 - 1e-5


def z_crit(confidence: float = CONFIDENCE) -> float:
    """Two-sided normal critical value for ``confidence``."""
    return float(stats.norm.isf((1.0 - confidence) / 2.0))


def record(id: str, claim: str, verdict: str, evidence: str, correction: str | None = None,
           counterexample: Any = None) -> dict:
    """One CONTRACTS §4 record ``{id, claim, verdict, evidence, correction, counterexample}``.

    A "fails" verdict must carry a counterexample or a computed difference (in
    ``counterexample``) and a correction that the same check verified.
    """
    if verdict not in VERDICTS:
        raise ValueError(f"verdict must be one of {VERDICTS}, got {verdict!r}")
    if verdict == "fails" and counterexample is None:
        raise ValueError(f"{id}: a 'fails' verdict needs a counterexample or a computed difference")
    return {"id": id, "claim": claim, "verdict": verdict, "evidence": evidence,
            "correction": correction, "counterexample": counterexample}


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
