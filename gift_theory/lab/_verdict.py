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
      proportional to the programmed weights nor a fixed linear map of them, nor are their
      rows coupled as the rows of the weights are; fitted bias offsets do not all go one way
      (:func:`~gift_theory.lab._fit_offsets.prior_check`: |z| < 4 in every layer, the coupling
      test's exact p above 0.01 over the layers);
   b'. an effect that acts through the acquisition times (``needs_times``: drift) is what the
      data show only if its time dependence is: the same fitted model with every time held at
      the file's mean (its time-free twin) must do worse on the held-out half by at least 2 sd
      (the ranking's cost of one parameter, here the trend's) -- else a constant gain does as
      well, and the data say nothing of a trend;
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

import dataclasses

import numpy as np

from ..effects import REGISTRY
from ._compare import failing_layers, one_step_check
from ._fit_offsets import refusing

ALPHA = 0.01


def explanation(top, baseline_cmp, top_steps=None, prior=(), twin=None) -> tuple[bool, list[str]]:
    """``(explained, reasons)`` by the module's rule; reasons say why not (or, when explained,
    what passed). ``twin``: the top model's held-out comparison with the times held at their
    mean (rule b'), when it acts through them."""
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
            "w_coupling": "weight offsets of layer {l} have rows coupled as the programmed weights' rows are (a "
                          "coupling between the inputs, not errors drawn per weight)",
            "b_mean": "bias offsets of layer {l} all go one way (a shifted transfer, not per-neuron draws of either "
                      "sign)"}
    for row in refusing(prior):
        why.append(f"the fitted {what[row['test']].format(l=row['layer'])}: z = {row['z']:.1f}"
                   + (f" (p = {row['p']:.2g})" if "p" in row else ""))
    unit = baseline_cmp.se if baseline_cmp.se > 0 else 1.0
    if twin is not None and twin.discrepancy - top.comparison.discrepancy < 2.0 * unit:
        why.append(f"with every acquisition time held at its mean, awgn + {name} does nearly as well (held-out "
                   f"discrepancy {twin.discrepancy:.3g} against {top.comparison.discrepancy:.3g}, "
                   f"{(twin.discrepancy - top.comparison.discrepancy) / unit:.1f} sd apart, less than the 2 sd a "
                   f"parameter must buy; p = {twin.p_value:.3g}): a constant gain does what its trend in time does, "
                   f"so the data show no trend")
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


def time_free(meas):
    """``meas`` with every acquisition time at the mean of its times (rule b')."""
    return dataclasses.replace(meas, t=np.full_like(meas.t, float(np.mean(meas.t))))


def verdict(session, ranking, meas, mechanisms, failing) -> tuple[bool, list, str]:
    """``(explained, reasons, line)`` of a diagnosis: the rule of this module on the top-ranked
    model (its fitted offsets checked against their prior on the fitting inputs; with taps, its
    one-step check on every input; an effect acting through the times, its time-free twin on
    the held-out half), and the plain line naming the closest model. ``session``: the
    diagnosis's :class:`~gift_theory.lab._diagnose.Session`."""
    top = ranking[0] if ranking else None
    baseline_cmp = session.baseline_comparison
    prior, top_steps, twin = (), None, None
    if top is not None and baseline_cmp.p_value < ALPHA and top.comparison.p_value >= ALPHA:
        prior = session.prior(top.model)
        top_steps = one_step_check(session.k_step, top.model, meas, own_level=False) if meas.has_taps else None
        if meas.t is not None and any(REGISTRY[e].needs_times for e in top.effects):
            twin = session.score(top.model, held_out=time_free(session.test_meas))
    explained, reasons = explanation(top, baseline_cmp, top_steps, prior, twin)
    closest = min(ranking, key=lambda c: c.comparison.discrepancy) if ranking else None
    return explained, reasons, verdict_line(explained, reasons, top, baseline_cmp, mechanisms, failing, closest)
