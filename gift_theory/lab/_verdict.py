"""Stage 8 of the lab: is the measurement explained, and if not, what remains and where to look.

**The rule** (reference §6 ``explained``). The data are explained when

1. the baseline (awgn, s fitted) passes its held-out test (p >= 0.01) and the layer-wise
   identification rejects none of its assumptions (no test names a class:
   :func:`~gift_theory.lab._mechanisms.named`, Holm-adjusted 0.01): nothing is
   missing. ``missing_effect_detected`` is still the held-out test's alone (reference §4): when
   only the identification rejects, the data are not explained while no missing effect is
   "detected". The held-out test compares per-input laws on half the inputs and has little
   power against a law or a variance pattern that the identification's signed tests see on all
   of them (Student-t noise in one layer of a tapped chip passed it at p = 0.40, kurtosis z =
   10.7); or
2. the top-ranked model passes its held-out test, and
   a. its parameters are identified by the data: every per-device offset family it fits is
      determined by the data rather than by its prior -- effective degrees of freedom at least
      half its number of values (:func:`~gift_theory.lab._offset_null.effective_dof`; without
      taps a few hundred weight offsets fitted to a few hundred output means are not: they can
      follow almost any smooth distortion of the network, so their passing says nothing); a
      model whose only offsets are per-neuron parameters is identified when each value is, neuron
      by neuron (:mod:`._neurons`: its standard error at most 1/sqrt(2) of the prior scale), and
      then the outlier test of rule b does not refuse its values (a dead neuron is a finding);
   b. its fitted values look like its own effect: fitted weight offsets are neither
      proportional to the programmed weights nor a fixed linear map of them, nor are their
      rows coupled as the rows of the weights are; fitted bias offsets do not all go one way
      (:func:`~gift_theory.lab._offset_prior.prior_check`: |z| < 4 in every layer, the coupling
      test's exact p above 0.01 over the layers);
   b'. an effect that acts through the acquisition times (``needs_times``: drift) is what the
      data show only if its time dependence is: the same fitted model with every time held at
      the file's mean (its time-free twin) must do worse on the held-out half by at least 2 sd
      (the ranking's cost of one parameter, here the trend's) -- else a constant gain does as
      well, and the data say nothing of a trend;
   b''. when the identification finds a trend in acquisition time (a time_drift test rejecting
      at Holm-adjusted 0.01), the model has an effect that acts through the times: the held-out
      test compares per-input means, which average an interleaved acquisition's trend away
      (without taps a bias drift passed as layer_gain, a gain drift as activation_gain;
      :func:`~gift_theory.lab._diagnose._identification_refusals`);
   b'''. when the baseline passes its held-out test but the identification rejects it (rule 1),
      a candidate with no effect of a class the identification flags is refused: that test
      did not see what the identification found, so its passing says nothing;
   e. without taps, it is not the case that every candidate of its class, put into the model and
      fitted to every input's mean (:mod:`._explain_output`), fails to reproduce the output's
      mean while another class's candidate reproduces it (an activation's shape and a readout's
      curve are one group there): the held-out test, on half the inputs, can pass what all the
      means reject;
   f. when the identification names noise_law by its kurtosis test, the model's own shots have
      the measured tails there, or at least tails moved from the baseline's towards them (each
      cell's kurtosis over the inputs against the model's and the baseline's own shots,
      :func:`~gift_theory.lab._diagnose._law_check`): a law change in the wrong direction can
      lower the held-out discrepancy (uniform noise passed on Student-t noise in one layer);
   g. when the identification names gain_fluctuation or correlated_noise (a covariance across a
      layer's neurons within a shot), the model's own shots have the measured pattern of
      correlations between neurons there (each pair's Fisher z, against the model's own spread
      over samples of r shots, :func:`~gift_theory.lab._diagnose._cov_check`), or one moved
      from the baseline's towards it and not far from it (p >= 1e-4): the held-out test reads
      each neuron's law alone, so per-neuron multiplicative noise passed on
      multiplicative + common-mode noise (p = 0.054, the shared gain at z = 14). A candidate
      refused by b'', b''', e, f or g lacks something the data show: when no candidate passes,
      the runners-up are fitted on top of the best one, as for one that fails its test;
   c. with taps, every layer of the fitted model passes its one-step check (at 0.01 with
      Bonferroni over the layers): the model is right where it acts, not only on average; and
   d. an effect fitted by its scalar parameters buys its keep: its penalised score (held-out
      discrepancy + 2 sd per parameter, the ranking's) is below the baseline's discrepancy --
      else the effect that passes may just absorb noise.

A model that fits anything is not an explanation: (a) and (b) refuse one that passed only
because it could follow whatever the chip did. The same checks give every candidate of the
ranking its status (:func:`refusals`; ``"refused"`` when one of a-g refuses a candidate that
passes its test), and the top-ranked model is the first that passes, else the first refused,
else the closest of those the data reject -- the one the verdict line names.

**Words follow the numbers.** A reason that speaks of how far the data are from a model says
it from that model's p-value (:func:`p_words`): "barely inconsistent" only for 1e-3 <= p < 0.01,
"inconsistent" down to 1e-6, "far from it" below, each with its p. When the data are not explained, the verdict
says what remains against the noise floor and which mechanism classes and layers to look at
(:mod:`._mechanisms`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._compare import failing_layers
from ._neurons import identified, outlier_tests
from ._offset_prior import refusing

ALPHA = 0.01


def p_words(p: float) -> str:
    """How far from a model its p-value puts the data, in words that never contradict it."""
    if p >= ALPHA:
        return f"consistent with it (p = {p:.3g})"
    if p >= 1e-3:
        return f"barely inconsistent with it (p = {p:.3g})"
    if p >= 1e-6:
        return f"inconsistent with it (p = {p:.3g})"
    return f"far from it (p = {p:.3g})"


def refusals(cand, baseline_cmp, steps=None, prior=(), twin=None) -> list[str]:
    """Why a candidate that passes its held-out test is still no explanation (rules a, b, b', c,
    d of the module); [] when none refuses it. ``steps``: its one-step checks (with taps);
    ``prior``: :func:`~gift_theory.lab._offset_prior.prior_check` rows of its fitted values;
    ``twin``: its held-out comparison with the times held at their mean, when it acts through
    them."""
    name = " + ".join(cand.effects)
    why = []
    # issue 48 hook (lab/_neurons.py): per-neuron values identified neuron by neuron are an
    # explanation -- rule a's count and rule b's outlier test do not refuse them
    per_neuron, _ = identified(cand.model)
    if (cand.nominal and cand.n_free < 0.5 * cand.nominal and any(cand.model.offsets)
            and not per_neuron):
        why.append(f"{name}'s {cand.nominal} fitted values are not identified by the data (effective degrees of "
                   f"freedom {cand.n_free:.0f}: the prior, not the data, sets most of them)")
    if not any(cand.model.offsets) and cand.score >= baseline_cmp.discrepancy:
        why.append(f"awgn + {name} lowers the held-out discrepancy by "
                   f"{baseline_cmp.discrepancy - cand.comparison.discrepancy:.3g}, less than its {cand.n_free:g} "
                   f"parameter(s) cost (2 sd each): it does not buy its keep (the data are "
                   f"{p_words(baseline_cmp.p_value).replace('it (', 'awgn (')})")
    what = {"w_correlation": "weight offsets of layer {l} are proportional to the programmed weights (a gain, not an "
                             "error drawn apart from them)",
            "w_structure": "weight offsets of layer {l} are a fixed linear map of the programmed weights (a coupling)",
            "w_coupling": "weight offsets of layer {l} have rows coupled as the programmed weights' rows are (a "
                          "coupling between the inputs, not errors drawn per weight)",
            "b_mean": "bias offsets of layer {l} all go one way (a shifted transfer, not per-neuron draws of either "
                      "sign)"}
    findings = outlier_tests(cand.model) if per_neuron else set()
    for row in refusing(prior):
        if row["test"] in findings:  # a neuron unlike the rest is the finding, not a refusal
            continue
        text = what.get(row["test"], row.get("what", f"{row['test']} of layer {{l}}")).format(l=row["layer"])
        why.append(f"the fitted {text}: z = {row['z']:.1f}" + (f" (p = {row['p']:.2g})" if "p" in row else ""))
    unit = baseline_cmp.se if baseline_cmp.se > 0 else 1.0
    if twin is not None and twin.discrepancy - cand.comparison.discrepancy < 2.0 * unit:
        why.append(f"with every acquisition time held at its mean, awgn + {name} does nearly as well (held-out "
                   f"discrepancy {twin.discrepancy:.3g} against {cand.comparison.discrepancy:.3g}, "
                   f"{(twin.discrepancy - cand.comparison.discrepancy) / unit:.1f} sd apart, less than the 2 sd a "
                   f"parameter must buy; p = {twin.p_value:.3g}): a constant does what its trend in time does, "
                   f"so the data show no trend")
    if steps:
        bad = failing_layers(steps)
        if bad:
            why.append(f"with {name} fitted, layer(s) {', '.join(map(str, bad))} still fail their one-step check")
    return why


def _rejected(baseline_cmp, flagged: dict, tail: str) -> str:
    """Rule 1's reason: the awgn model passes its held-out test, the identification rejects it."""
    found = ", ".join(f"{k} (p = {v:.2g})" for k, v in sorted(flagged.items(), key=lambda kv: kv[1]))
    return (f"the awgn model passes its held-out test (p = {baseline_cmp.p_value:.3g}), but the identification "
            f"rejects it: {found}; {tail}")


def explanation(top, baseline_cmp, top_steps=None, prior=(), twin=None, flagged=None) -> tuple[bool, list[str]]:
    """``(explained, reasons)`` by the module's rule for the top-ranked candidate; reasons say
    why not (or, when explained, what passed). A candidate that carries its status (ranked by
    :func:`~gift_theory.lab._diagnose.diagnose`) is judged by it; otherwise its checks are
    made here from ``top_steps``, ``prior`` and ``twin`` (:func:`refusals`). ``flagged``:
    ``{class: Holm-adjusted p}`` of the classes the identification's tests name (rule 1)."""
    if baseline_cmp.p_value >= ALPHA and not flagged:
        return True, [f"the awgn model passes (p = {baseline_cmp.p_value:.3g}): nothing is missing"]
    if baseline_cmp.p_value >= ALPHA and (top is None or top.comparison.p_value < ALPHA):
        return False, [_rejected(baseline_cmp, flagged, "the held-out test does not see this")]
    if top is None:
        return False, ["no candidate was tried"]
    name = " + ".join(top.effects)
    if top.comparison.p_value < ALPHA:
        return False, [f"the best model, awgn + {name}, fails its held-out test (p = {top.comparison.p_value:.3g}; "
                       f"the baseline's p = {baseline_cmp.p_value:.3g})"]
    status = getattr(top, "status", "")
    why = list(top.refused_because) if status else refusals(top, baseline_cmp, top_steps, prior, twin)
    if why and baseline_cmp.p_value >= ALPHA and flagged:  # rule 1 first: what the user must read
        why = [_rejected(baseline_cmp, flagged, "no candidate with a term for it explains the data")] + why
    if why:
        return False, why
    per_neuron, said = identified(top.model)
    return True, [f"awgn + {name} passes its held-out test (p = {top.comparison.p_value:.3g}) and every check of "
                  f"its fitted values" + (f"; {said}" if per_neuron else "")]


def _pm(value: float, sd: float) -> str:
    """``value +- sd`` as the verdict line prints it (``+- sd`` left out when it is not finite)."""
    return f"{value:.4g} +- {sd:.2g}" if np.isfinite(sd) else f"{value:.4g}"


def verdict_line(explained: bool, reasons, top, baseline_cmp, mechanisms, failing, closest=None,
                 flagged=None) -> str:
    """The one plain line of ``gift diagnose``. It names ``top`` (ranking[0]); ``closest``, when
    given, is said to be what remains instead (old callers; the diagnosis passes none);
    ``flagged`` as in :func:`explanation`."""
    closest = top if closest is None else closest
    if explained:
        if baseline_cmp.p_value >= ALPHA and not flagged:
            return (f"explained: the awgn model fits the data (p = {baseline_cmp.p_value:.3g}); no physical effect "
                    f"is missing")
        # each number with its spread: a discrepancy of 8.8 reads as a failure against a floor of
        # 0.73 until the floor's +- 5.2 and the model's own sd under it are beside them
        return (f"explained: awgn + {' + '.join(top.effects)} fits the held-out data (p = "
                f"{top.comparison.p_value:.3g}, discrepancy {_pm(top.comparison.discrepancy, top.comparison.se)} "
                f"against a floor of {_pm(baseline_cmp.noise_floor, baseline_cmp.floor_se)})")
    best = (f"the closest model, awgn + {' + '.join(closest.effects)}, leaves a held-out discrepancy of "
            f"{_pm(closest.comparison.discrepancy, closest.comparison.se)} (p = {closest.comparison.p_value:.3g}) "
            f"against a floor of {_pm(baseline_cmp.noise_floor, baseline_cmp.floor_se)}" if closest is not None else "")
    where = ""
    if mechanisms:
        parts = [f"{m['mechanism']}" + (f" in layer(s) {', '.join(map(str, m['layers']))}" if m["layers"] else "")
                 for m in mechanisms[:3]]
        where = "; look at " + ", then ".join(parts)
    elif failing:
        where = f"; look at layer(s) {', '.join(map(str, failing))}"
    if baseline_cmp.p_value >= ALPHA and flagged:  # rule 1: the awgn model passes, the identification rejects it
        best = (best + "; " if best else "") + reasons[0]
    elif top is not None and top.comparison.p_value >= ALPHA:
        best += f"; awgn + {' + '.join(top.effects)} passes its test, but {reasons[0]}"
    return "NOT EXPLAINED: nothing gift knows explains these data -- " + best + where


def as_json_fields(explained: bool, reasons, line: str, failing, mechanisms) -> dict:
    return {"explained": bool(explained), "verdict": line, "reasons": list(reasons),
            "failing_layers": None if failing is None else [int(l) for l in failing],
            "mechanisms": [dict(m, score=float(np.round(m["score"], 3)),
                                **({"p_value": float(m["p_value"])} if m.get("p_value") is not None else {}))
                           for m in mechanisms]}


def time_free(meas):
    """``meas`` with every acquisition time at the mean of its times (rule b')."""
    return dataclasses.replace(meas, t=np.full_like(meas.t, float(np.mean(meas.t))))


def verdict(session, ranking, meas, mechanisms, failing, flagged=None) -> tuple[bool, list, str]:
    """``(explained, reasons, line)`` of a diagnosis: the rule of this module on ranking[0], whose
    checks :meth:`~gift_theory.lab._diagnose.Session.checks` made (its status), and the plain
    line naming it. ``session``: the diagnosis's :class:`~gift_theory.lab._diagnose.Session`."""
    top = ranking[0] if ranking else None
    explained, reasons = explanation(top, session.baseline_comparison, flagged=flagged)
    return explained, reasons, verdict_line(explained, reasons, top, session.baseline_comparison, mechanisms,
                                            failing, flagged=flagged)
