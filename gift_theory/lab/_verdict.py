"""Stage 8 of the lab: is the measurement explained, and if not, what remains and where to look.

**The rule** (CONTRACTS §6 ``explained``). The data are explained when

1. the baseline (awgn, s fitted) passes its held-out test (p >= 0.01): nothing is missing; or
2. the top-ranked model passes its held-out test, and
   a. its parameters are identified by the data: every per-device offset family it fits is
      determined by the data rather than by its prior -- effective degrees of freedom at least
      half its number of values (:func:`~gift_theory.lab._fit_offsets.effective_dof`; without
      taps a few hundred weight offsets fitted to a few hundred output means are not: they can
      follow almost any smooth distortion of the network, so their passing says nothing);
   b. its fitted values look like its own effect: fitted weight offsets are neither
      proportional to the programmed weights nor a fixed linear map of them, fitted bias
      offsets do not all go one way (:func:`~gift_theory.lab._fit_offsets.prior_check`,
      |z| < 4 in every layer);
   c. with taps, every layer of the fitted model passes its one-step check (at 0.01 with
      Bonferroni over the layers): the model is right where it acts, not only on average; and
   d. an effect fitted by its scalar parameters buys its keep: its penalised score (held-out
      discrepancy + 2 sd per parameter, the ranking's) is below the baseline's discrepancy --
      else the data are only barely inconsistent with awgn and the effect that passes may just
      absorb noise.

A model that fits anything is not an explanation: (a) and (b) refuse one that passed only
because it could follow whatever the chip did. When the data are not explained, the verdict
says what remains against the noise floor and which mechanism classes and layers to look at
(:mod:`._mechanisms`).
"""

from __future__ import annotations

import numpy as np

from ._compare import failing_layers, one_step_check
from ._fit_offsets import prior_check

ALPHA = 0.01
#: the z beyond which fitted offsets are not the effect's own (a structure the prior excludes)
PRIOR_Z = 4.0


def explanation(top, baseline_cmp, top_steps=None, prior=()) -> tuple[bool, list[str]]:
    """``(explained, reasons)`` by the module's rule; reasons say why not (or, when explained,
    what passed)."""
    if baseline_cmp.p_value >= ALPHA:
        return True, [f"the awgn model passes (p = {baseline_cmp.p_value:.3g}): nothing is missing"]
    if top is None:
        return False, ["no candidate was tried"]
    name = " + ".join(top.effects)
    why = []
    if top.comparison.p_value < ALPHA:
        why.append(f"the best model, awgn + {name}, fails its held-out test (p = {top.comparison.p_value:.3g})")
    if top.nominal and top.n_free < 0.5 * top.nominal and any(top.model.offsets):
        why.append(f"{name}'s {top.nominal} fitted values are not identified by the data (effective degrees of "
                   f"freedom {top.n_free:.0f}: the prior, not the data, sets most of them)")
    if not any(top.model.offsets) and top.score >= baseline_cmp.discrepancy:
        why.append(f"awgn + {name} lowers the held-out discrepancy by {baseline_cmp.discrepancy - top.comparison.discrepancy:.3g}"
                   f", less than its {top.n_free:g} parameter(s) cost (2 sd each): the data are barely inconsistent "
                   f"with awgn and no effect buys its keep")
    what = {"w_correlation": "weight offsets of layer {l} are proportional to the programmed weights (a gain, not an "
                             "error drawn apart from them)",
            "w_structure": "weight offsets of layer {l} are a fixed linear map of the programmed weights (a coupling)",
            "b_mean": "bias offsets of layer {l} all go one way (a shifted transfer, not per-neuron draws of either "
                      "sign)"}
    for row in prior or ():
        if abs(row["z"]) > PRIOR_Z:
            why.append(f"the fitted {what[row['test']].format(l=row['layer'])}: z = {row['z']:.1f}")
    if top_steps:
        bad = failing_layers(top_steps)
        if bad:
            why.append(f"with {name} fitted, layer(s) {', '.join(map(str, bad))} still fail their one-step check")
    if why:
        return False, why
    return True, [f"awgn + {name} passes its held-out test (p = {top.comparison.p_value:.3g}) and every check of "
                  f"its fitted values"]


def verdict_line(explained: bool, reasons, top, baseline_cmp, mechanisms, failing, closest=None) -> str:
    """The one plain line of ``gift diagnose``; ``closest``: the candidate with the lowest
    held-out discrepancy (what remains is said of it; default ``top``)."""
    closest = top if closest is None else closest
    if explained:
        if baseline_cmp.p_value >= ALPHA:
            return (f"explained: the awgn model fits the data (p = {baseline_cmp.p_value:.3g}); no physical effect "
                    f"is missing")
        return (f"explained: awgn + {' + '.join(top.effects)} fits the held-out data (p = "
                f"{top.comparison.p_value:.3g}, discrepancy {top.comparison.discrepancy:.4g} against a floor of "
                f"{baseline_cmp.noise_floor:.4g})")
    best = (f"the closest model, awgn + {' + '.join(closest.effects)}, leaves a held-out discrepancy of "
            f"{closest.comparison.discrepancy:.4g} (p = {closest.comparison.p_value:.3g}) against a floor of "
            f"{baseline_cmp.noise_floor:.4g} +- {baseline_cmp.floor_se:.2g}" if closest is not None else "")
    where = ""
    if mechanisms:
        parts = [f"{m['mechanism']}" + (f" in layer(s) {', '.join(map(str, m['layers']))}" if m["layers"] else "")
                 for m in mechanisms[:3]]
        where = "; look at " + ", then ".join(parts)
    elif failing:
        where = f"; look at layer(s) {', '.join(map(str, failing))}"
    return ("NOT EXPLAINED: nothing gift knows explains these data -- " + best
            + ("" if top is None or top.comparison.p_value < ALPHA else f"; awgn + {' + '.join(top.effects)} passes, "
               f"but {reasons[0]}") + where)


def as_json_fields(explained: bool, reasons, line: str, failing, mechanisms) -> dict:
    return {"explained": bool(explained), "verdict": line, "reasons": list(reasons),
            "failing_layers": None if failing is None else [int(l) for l in failing],
            "mechanisms": [dict(m, score=float(np.round(m["score"], 3))) for m in mechanisms]}


def verdict(key, ranking, baseline_cmp, fit_meas, meas, mechanisms, failing) -> tuple[bool, list, str]:
    """``(explained, reasons, line)`` of a diagnosis: the rule of this module on the top-ranked
    model (its fitted offsets checked against their prior on the fitting inputs; with taps, its
    one-step check on every input), and the plain line naming the closest model."""
    top = ranking[0] if ranking else None
    prior, top_steps = (), None
    if top is not None and baseline_cmp.p_value < ALPHA and top.comparison.p_value >= ALPHA:
        prior = prior_check(top.model, fit_meas)
        top_steps = one_step_check(key, top.model, meas, own_level=False) if meas.has_taps else None
    explained, reasons = explanation(top, baseline_cmp, top_steps, prior)
    closest = min(ranking, key=lambda c: c.comparison.discrepancy) if ranking else None
    return explained, reasons, verdict_line(explained, reasons, top, baseline_cmp, mechanisms, failing, closest)
