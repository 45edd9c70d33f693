"""Stage 8 of the lab: is the measurement explained, and if not, what remains and where to look.

**The rule** (reference §6 ``explained``). The data are explained when

1. *nothing missing*: the baseline (awgn, s fitted) passes its held-out test (p >= 0.01) and the
layer-wise
   identification rejects none of its assumptions (no test names a class:
   :func:`~gift_theory.lab._mechanisms.named`, Holm-adjusted 0.01): nothing is
   missing. ``missing_effect_detected`` is still the held-out test's alone (reference §4): when
   only the identification rejects, the data are not explained while no missing effect is
   "detected". The held-out test compares per-input laws on half the inputs and has little
   power against a law or a variance pattern that the identification's signed tests see on all
   of them (Student-t noise in one layer of a tapped chip passed it at p = 0.40, kurtosis z =
   10.7); or
2. the top-ranked model passes its held-out test, and each of these holds (the rules' names):
   * *identified values*: its parameters are identified by the data: every per-device offset
     family it fits is determined by the data rather than by its prior -- effective degrees of
     freedom at least half its number of values
     (:func:`~gift_theory.lab._offset_null.effective_dof`; without taps a few hundred weight
     offsets fitted to a few hundred output means are not: they can follow almost any smooth
     distortion of the network, so their passing says nothing); a model whose only offsets are
     per-neuron parameters is identified when each value is, neuron by neuron (:mod:`._neurons`:
     its standard error at most 1/sqrt(2) of the prior scale), and then the outlier test of *its
     own effect's values* does not refuse its values (a dead neuron is a finding);
   * *its own effect's values*: its fitted values look like its own effect: fitted weight
     offsets are neither proportional to the programmed weights nor a fixed linear map of them,
     nor are their rows coupled as the rows of the weights are; fitted bias offsets do not all
     go one way (:func:`~gift_theory.lab._offset_prior.prior_check`: |z| < 4 in every layer, the
     coupling test's exact p above 0.01 over the layers);
   * *a trend that buys its keep* (:func:`time_free`): an effect that acts through the
     acquisition times (``needs_times``: drift) is what the data show only if its time
     dependence is: the same fitted model with every time held at the file's mean (its time-free
     twin) must do worse on the held-out half by at least 2 sd (the ranking's cost of one
     parameter, here the trend's) -- else a constant gain does as well, and the data say nothing
     of a trend;
   * *a trend the identification finds* (:func:`refuse_untimed_under_a_trend`; the memory's lag
     test likewise, :func:`refuse_no_memory_where_found` and :func:`refuse_a_memory_not_found`):
     when the identification finds a trend in acquisition time (a time_drift test rejecting at
     Holm-adjusted 0.01), the model has an effect that acts through the times: the held-out test
     compares per-input means, which average an interleaved acquisition's trend away (without
     taps a bias drift passed as layer_gain, a gain drift as activation_gain;
     :func:`identification_refusals`);
   * *what the held-out test cannot see* (:func:`refuse_what_the_held_out_test_cannot_see`):
     when the baseline passes its held-out test but the identification rejects it (*nothing
     missing* fails), a candidate with no effect of a class the identification flags is refused:
     that test did not see what the identification found, so its passing says nothing;
   * *the output's means* (:func:`refuse_where_the_output_means_disagree`): without taps, it is
     not the case that every candidate of its class, put into the model and fitted to every
     input's mean (:mod:`._explain_output`), fails to reproduce the output's mean while another
     class's candidate reproduces it (an activation's shape and a readout's curve are one group
     there): the held-out test, on half the inputs, can pass what all the means reject;
   * *the tails* (:func:`unmoved_tails_rule`): when the identification names noise_law by its
     kurtosis test, the model's own shots have the measured tails there, or at least tails moved
     from the baseline's towards them (each cell's kurtosis over the inputs against the model's
     and the baseline's own shots, :func:`unmoved_tails_rule`): a law change in the wrong
     direction can lower the held-out discrepancy (uniform noise passed on Student-t noise in
     one layer);
   * *the correlations* (:func:`unreproduced_correlations_rule`): when the identification names
     gain_fluctuation or correlated_noise (a covariance across a layer's neurons within a shot),
     the model's own shots have the measured pattern of correlations between neurons there (each
     pair's Fisher z, against the model's own spread over samples of r shots), or one moved from
     the baseline's towards it and not far from it (p >= 1e-4): the held-out test reads each
     neuron's law alone, so per-neuron multiplicative noise passed on multiplicative +
     common-mode noise (p = 0.054, the shared gain at z = 14). A candidate refused by one of the
     identification's rules (but a memory not found) lacks something the data show: when no
     candidate passes, the runners-up are fitted on top of the best one, as for one that fails
     its test;
   * *every layer right*: with taps, every layer of the fitted model passes its one-step check
     (at 0.01 with Bonferroni over the layers): the model is right where it acts, not only on
     average; and
   * *buys its keep*: an effect fitted by its scalar parameters buys its keep: its penalised
     score (held-out discrepancy + 2 sd per parameter, the ranking's) is below the baseline's
     discrepancy -- else the effect that passes may just absorb noise. Or, when the baseline
     passes its held-out test and the identification rejects it, an effect of a class the
     identification names buys its keep *where the identification looked*
     (:func:`found_reproduced_rule`): the identification run on the
     candidate's own campaigns reproduces every test that rejects awgn, and run on the
     baseline's it does not -- on a small file the held-out half cannot pay for a parameter
     that the identification's tests, pooled over every input, plainly need.

A model that fits anything is not an explanation: *identified values* and *its own effect's
values* refuse one that passed only because it could follow whatever the chip did. The same
checks give every candidate of the ranking its status (:func:`refusals` and
:func:`identification_refusals`; ``"refused"`` when one of them refuses a candidate that passes
its test), and the top-ranked model is the first that passes, else the first refused,
else the closest of those the data reject -- the one the verdict line names.

**Words follow the numbers.** A reason that speaks of how far the data are from a model says
it from that model's p-value (:func:`p_words`): "barely inconsistent" only for 1e-3 <= p < 0.01,
"inconsistent" down to 1e-6, "far from it" below, each with its p. When the data are not
explained, the verdict
says what remains against the noise floor and which mechanism classes and layers to look at
(:mod:`._mechanisms`).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from scipy import stats

from .._model import named_subkey
from ..effects import REGISTRY
from ._budget import default_workers, map_in_threads, one_blas_thread
from ._compare import failing_layers
from ._explain_output import mean_refusal
from ._level import ALPHA
from ._mechanisms import named
from ._neurons import identified, outlier_tests
from ._offset_prior import refusing
from ._qtest import over_inputs
from ._shots import model_shots
from .identification import identify
from .identification._layers import _subset
from .identification._stats import _shots_law, _two_sided


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
    """Why a candidate that passes its held-out test is still no explanation: the sentences of
    :func:`refusal_rules`."""
    return [why for _, why in refusal_rules(cand, baseline_cmp, steps, prior, twin)]


def refusal_rules(cand, baseline_cmp, steps=None, prior=(), twin=None) -> list[tuple[str, str]]:
    """Why a candidate that passes its held-out test is still no explanation, as ``(rule,
    sentence)`` pairs: ``identified`` (*identified values*), ``keep`` (*buys its keep*),
    ``prior`` (*its own effect's values*), ``time_free_twin`` (*a trend that buys its keep*),
    ``one_step`` (*every layer right*); [] when none refuses it. ``steps``: its one-step checks
    (with taps); ``prior``: :func:`~gift_theory.lab._offset_prior.prior_check` rows of its fitted
    values; ``twin``: its held-out comparison with the times held at their mean, when it acts
    through them."""
    name = " + ".join(cand.effects)
    why = []
    # per-neuron values identified neuron by neuron (._neurons) are an explanation: the count of
    # identified values and the outlier test of its own effect's values do not refuse them
    per_neuron, _ = identified(cand.model)
    if (cand.nominal and cand.n_free < 0.5 * cand.nominal and any(cand.model.offsets)
            and not per_neuron):
        why.append(("identified", f"{name}'s {cand.nominal} fitted values are not identified by the data (effective "
                                  f"degrees of freedom {cand.n_free:.0f}: the prior, not the data, sets most of them)"))
    keep = keep_refusal(cand, baseline_cmp)
    if keep:
        why.append(("keep", keep))
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
        why.append(("prior", f"the fitted {text}: z = {row['z']:.1f}" + (f" (p = {row['p']:.2g})" if "p" in row else "")))
    unit = baseline_cmp.se if baseline_cmp.se > 0 else 1.0
    if twin is not None and twin.discrepancy - cand.comparison.discrepancy < 2.0 * unit:
        why.append(("time_free_twin",
                    f"with every acquisition time held at its mean, awgn + {name} does nearly as well (held-out "
                    f"discrepancy {twin.discrepancy:.3g} against {cand.comparison.discrepancy:.3g}, "
                    f"{(twin.discrepancy - cand.comparison.discrepancy) / unit:.1f} sd apart, less than the 2 sd a "
                    f"parameter must buy; p = {twin.p_value:.3g}): a constant does what its trend in time does, "
                    f"so the data show no trend"))
    if steps:
        bad = failing_layers(steps)
        if bad:
            why.append(("one_step", f"with {name} fitted, layer(s) {', '.join(map(str, bad))} still fail their "
                                    "one-step check"))
    return why


def keep_refusal(cand, baseline_cmp) -> str | None:
    """*Buys its keep*: the sentence refusing an effect fitted by its scalar parameters whose
    penalised score is not below the baseline's held-out discrepancy, else None."""
    if any(cand.model.offsets) or cand.score < baseline_cmp.discrepancy:
        return None
    return (f"awgn + {' + '.join(cand.effects)} lowers the held-out discrepancy by "
            f"{baseline_cmp.discrepancy - cand.comparison.discrepancy:.3g}, less than its {cand.n_free:g} "
            f"parameter(s) cost (2 sd each): it does not buy its keep (the data are "
            f"{p_words(baseline_cmp.p_value).replace('it (', 'awgn (')})")


def _rejected(baseline_cmp, flagged: dict, tail: str) -> str:
    """*Nothing missing* fails: the awgn model passes its held-out test, the identification rejects it."""
    found = ", ".join(f"{k} (p = {v:.2g})" for k, v in sorted(flagged.items(), key=lambda kv: kv[1]))
    return (f"the awgn model passes its held-out test (p = {baseline_cmp.p_value:.3g}), but the identification "
            f"rejects it: {found}; {tail}")


def explanation(top, baseline_cmp, top_steps=None, prior=(), twin=None, flagged=None) -> tuple[bool, list[str]]:
    """``(explained, reasons)`` by the module's rule for the top-ranked candidate; reasons say
    why not (or, when explained, what passed). A candidate that carries its status (ranked by
    :func:`~gift_theory.lab.diagnose`) is judged by it; otherwise its checks are
    made here from ``top_steps``, ``prior`` and ``twin`` (:func:`refusals`). ``flagged``:
    ``{class: Holm-adjusted p}`` of the classes the identification's tests name (*nothing missing*)."""
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
    if why and baseline_cmp.p_value >= ALPHA and flagged:  # nothing missing fails first: what the user must read
        why = [_rejected(baseline_cmp, flagged, "no candidate with a term for it explains the data")] + why
    if why:
        return False, why
    per_neuron, said = identified(top.model)
    bought = getattr(top, "bought_by", "")
    return True, [f"awgn + {name} passes its held-out test (p = {top.comparison.p_value:.3g}) and every check of "
                  f"its fitted values" + (f"; {said}" if per_neuron else "")] + ([bought] if bought else [])


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
    if baseline_cmp.p_value >= ALPHA and flagged:  # the awgn model passes, the identification rejects it
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
    """``meas`` with every acquisition time at the mean of its times (*a trend that buys its keep*)."""
    return dataclasses.replace(meas, t=np.full_like(meas.t, float(np.mean(meas.t))))


def verdict(session, ranking, meas, mechanisms, failing, flagged=None) -> tuple[bool, list, str]:
    """``(explained, reasons, line)`` of a diagnosis: the rule of this module on ranking[0], whose
    checks :meth:`~gift_theory.lab.Session.checks` made (its status), and the plain
    line naming it. ``session``: the diagnosis's :class:`~gift_theory.lab.Session`."""
    top = ranking[0] if ranking else None
    explained, reasons = explanation(top, session.baseline_comparison, flagged=flagged)
    return explained, reasons, verdict_line(explained, reasons, top, session.baseline_comparison, mechanisms,
                                            failing, flagged=flagged)


def mechanism_classes(name: str) -> set:
    """The mechanism classes of a candidate named ``effect+effect...``."""
    return {REGISTRY[e].mechanism for e in name.split("+")}


# ---- the rules of the identification: what the held-out test cannot see -----------------------

def _refuse(c, why, rule: str, lacks: bool = False):
    return dataclasses.replace(c, status="refused", refused_because=tuple(c.refused_because) + (why,),
                               refused_for=tuple(c.refused_for) + (rule,),
                               lacks=c.lacks or lacks)


def _where(rows) -> str:
    best = min(rows, key=lambda r: r["p_adj"])
    return f"at layer(s) {', '.join(map(str, sorted({int(r['layer']) for r in rows})))}, p = {best['p_adj']:.2g}"


def unmoved_tails_rule(session, ident):
    """The tails rule, or None when it has nothing to read: when the identification
    names noise_law by its kurtosis test, a passing candidate must move the shots' tails from
    the baseline's towards the measured ones. Its own shots and the baseline's (4 r per input,
    the measurement's inputs and times, keys named by the effects) are cut into samples of r,
    and each cell's Anscombe-Glynn z of their kurtosis compared over the inputs (Bonferroni over
    the layers named). A candidate is refused where its tails differ from the measured ones
    (two-sided) and have not moved towards them from the baseline's (one-sided, both at 0.01):
    a law with the measured tails passes, and so does the right law fitted a little short
    (multiplicative noise on a tapped chip: +0.56 against +0.71 measured, the baseline's
    +0.01), but not one whose tails go the other way. Without it uniform noise "explained"
    Student-t noise in one layer (the kurtosis test had named noise_law, +0.22 beyond awgn's; a
    law with lighter tails than the Gaussian's lowered the held-out discrepancy by 0.1 sd)."""
    meas = session.meas
    rows = [r for r in ([] if ident is None else ident.rows())
            if r["class"] == "noise_law" and r["test"] == "kurtosis" and named(r, ident.taps)]
    if not rows or meas.r < 5:
        return None
    ids, data, r = list(meas.layer_ids()), meas.layers(), meas.r
    m = len(rows)

    def laws(model, name):
        own = model_shots(named_subkey(session.k_cmp, "law/" + name), model, meas, 4 * r)
        return [_shots_law(own[ids.index(int(row["layer"]))], r) for row in rows]

    measured = [_shots_law(data[ids.index(int(row["layer"]))], r) for row in rows]

    def compare(i, lb, lc):
        ld = measured[i]
        z = over_inputs((ld[1] - lc[1]).mean(1))
        p = min(1.0, m * _two_sided(z))
        toward = np.sign(float(np.mean(ld[1] - lb[1]))) * over_inputs((lc[1] - lb[1]).mean(1))
        p_toward = min(1.0, m * float(stats.norm.sf(toward)))
        if p < ALPHA and p_toward >= ALPHA:
            return p, z, int(rows[i]["layer"]), float(ld[0].mean()), float(lc[0].mean()), float(lb[0].mean())
        return None

    def say(name, worst) -> str:
        p, z, l, kd, kc, kb = worst
        return (f"awgn + {name} does not move the shots' tails towards the measured ones at layer {l}, where the "
                f"identification names noise_law: sample excess kurtosis {kd:+.2f} measured, {kc:+.2f} in its own "
                f"shots, {kb:+.2f} in the baseline's (z = {z:.1f}, p = {p:.2g})")

    return _against_baseline(session, laws, compare, say)


#: the correlations rule refuses a candidate whose correlations differ at this level (Bonferroni over the
#: layers) even when they moved from the baseline's towards the measured ones
STRICT = 1e-4


def _corr_z(shots, r: int):
    """(n, K // r, pairs): per input and sample of r consecutive shots of ``shots`` (n, K, d),
    Fisher's z (atanh) of the correlation of each pair of neurons (on at most
    :data:`~gift_theory.lab.identification._layers.WIDE` of them) -- a measurement's r shots (one sample) or a
    model's K."""
    n, K, d = shots.shape
    sub = _subset(d)
    x = np.asarray(shots, np.float64)[:, :K // r * r, sub].reshape(n, K // r, r, len(sub))
    x = x - x.mean(2, keepdims=True)
    x = x / np.maximum(np.sqrt(np.sum(x * x, 2, keepdims=True)), 1e-300)
    iu = np.triu_indices(len(sub), 1)
    # one sample at a time: the (n, d, d) products of all K // r at once were 8 times the memory
    c = np.stack([np.matmul(x[:, j].transpose(0, 2, 1), x[:, j])[:, iu[0], iu[1]] for j in range(x.shape[1])], 1)
    return np.arctanh(np.clip(c, -1 + 1e-12, 1 - 1e-12))


def unreproduced_correlations_rule(session, ident):
    """The correlations rule, or None when it has nothing to read: when the identification
    names gain_fluctuation or correlated_noise (a covariance across a layer's neurons within a
    shot), a passing candidate must reproduce the pattern of the shots' correlations between
    neurons, or move it from the baseline's towards the measured one. The held-out test
    compares each neuron's law on its own and cannot see a correlation: per-neuron
    multiplicative noise "explained" multiplicative + common-mode noise (p = 0.054) while the
    identification found the shared gain at z = 14.

    Each pair's correlation, Fisher's z of r shots: the measured one z_d per input; a model's
    k r shots (keys named by the effects; k = 8, or 4 where 8 r would not fit in memory) cut
    into k samples of r, their mean and variance.
    Per input, the mean over pairs of (z_d - mean)^2 - (1 + 1/k) var has mean zero when the model's
    shots have the measured correlations (whatever their law: the variance is the model's own
    over samples of r) and grows with every pair's difference; its mean over the inputs
    (one-sided, Bonferroni over the layers named) tests the candidate. It has moved towards the
    measured pattern when (z_d - mean)^2 - var / k is smaller for it than for the baseline
    (each estimates the squared difference plus the measurement's own variance, the same for
    both). Refused: differs (p < 0.01) and has not moved (one-sided p >= 0.01), or differs at
    p < :data:`STRICT` however far it moved. A right effect whose parameter is fitted a little
    off leaves a small difference that hundreds of pairs over hundreds of inputs can see (the
    blind sets' right candidates: z up to 2.7, weight_error without taps); a model that moves
    part of the way by another mechanism leaves more (per-neuron multiplicative noise on
    multiplicative + common-mode noise without taps: z = 4.5, having moved from the baseline's
    z = 9.6, where the pair leaves -0.2)."""
    meas = session.meas
    rows = {int(r["layer"]): r for r in ([] if ident is None else ident.rows())
            if r["class"] in ("gain_fluctuation", "correlated_noise") and named(r, ident.taps)}
    ids, data, r = list(meas.layer_ids()), meas.layers(), meas.r
    layers = sorted(l for l in rows if data[ids.index(l)].shape[-1] > 1)
    if not layers or r < 5:
        return None
    m = len(layers)

    def moments(model, name):
        own = model_shots(named_subkey(session.k_cmp, "corr/" + name), model, meas, k * r)
        out = []
        for l in layers:
            z = _corr_z(own[ids.index(l)], r)
            out.append((z.mean(1), z.var(1, ddof=1)))
        return out

    measured = [_corr_z(data[ids.index(l)], r)[:, 0] for l in layers]
    # a model's samples of r shots: 8 where the shots fit in ~1 GB (fewer samples leave its
    # own sampling in the statistic: one model under four keys gave z = 3.5 to 5.1)
    k = 8 if 8 * meas.r * meas.n * sum(int(np.prod(a.shape[2:])) for a in data) * 8 < 1e9 else 4
    def compare(i, base, cand):
        (mb, vb), (mc, vc), zd = base, cand, measured[i]
        dc, db = (zd - mc) ** 2, (zd - mb) ** 2
        z = over_inputs((dc - (1 + 1 / k) * vc).mean(1))
        p = min(1.0, m * float(stats.norm.sf(z)))
        toward = over_inputs(((db - vb / k) - (dc - vc / k)).mean(1))
        p_toward = min(1.0, m * float(stats.norm.sf(toward)))
        if p < ALPHA and (p_toward >= ALPHA or p < STRICT):
            return (p, z, layers[i], float(np.sqrt(max(np.mean(dc - (1 + 1 / k) * vc), 0.0))),
                    float(np.sqrt(max(np.mean(db - (1 + 1 / k) * vb), 0.0))), p_toward < ALPHA)
        return None

    def say(name, worst) -> str:
        p, z, l, rc, rb, moved = worst
        return (f"awgn + {name} does not reproduce the correlations between the neurons of layer {l}, where the "
                f"identification names {rows[l]['class']}" + (", though it moves them from the baseline's towards "
                "the measured ones" if moved else ", nor move them towards the measured ones") + ": rms "
                f"difference of their Fisher z {rc:.3f} beyond sampling (the baseline's {rb:.3f}; z = {z:.1f}, "
                f"p = {p:.2g})")

    return _against_baseline(session, moments, compare, say)


def _against_baseline(session, stats_of, compare, say):
    """The skeleton of the tails and the correlations rules: ``check(candidate)``, the sentence refusing it or None.
    ``stats_of(model, name)``: per layer tested, a statistic of the model's own shots (the
    baseline's made once, at the first candidate that needs them); ``compare(i, baseline's,
    candidate's)`` at the i-th layer tested: None, or a tuple starting with the p-value that
    refuses; the smallest p's tuple (the first on a tie) is what ``say(name, tuple)`` words."""
    base = []

    def check(c) -> str | None:
        if not base:
            base.extend(stats_of(session.baseline, "awgn"))
        hits = [h for h in (compare(i, b, own) for i, (b, own) in
                            enumerate(zip(base, stats_of(c.model, "+".join(c.effects))))) if h is not None]
        return say(" + ".join(c.effects), min(hits, key=lambda h: h[0])) if hits else None

    return check


def _signed(row) -> float:
    """An identification row's z with the sign of its effect size (a kurtosis beyond the
    model's, a variance's slope against the signal, ...; + where the effect is 0)."""
    z = float(np.clip(float(row["z"]), -40.0, 40.0))  # a p of 1 or 0 read as z = -inf or inf
    return z * (-1.0 if float(row["effect"]) < 0 else 1.0)


def _key(row) -> tuple:
    """Which test an identification row is, to read it off another campaign: class, test and
    layer (0 for the test across the layers, whose ``layer`` is the one that stands out)."""
    return row["class"], row["test"], 0 if row["test"] == "levels" else int(row["layer"])


#: the first stage's level: the first half of the campaigns refuses a candidate below it (with
#: the second stage's 0.01, a right candidate is refused at most 0.011 of the time)
EARLY = 1e-3

#: the identification is run on this many of a candidate's own campaigns (the spread of each
#: flagged test's z under the candidate; :func:`found_reproduced_rule`)
REPLICATES = 16


def found_reproduced_rule(session, ident):
    """*Bought where the identification looked*, or None when it has nothing to read (the
    baseline fails its held-out test, or the identification names no class): the check of a
    candidate refused only because it does not buy its keep on the held-out half, while the
    baseline passes that half and the identification rejects the baseline. The held-out test
    has little power where the identification's signed tests, pooled over every input, have
    much (a correctly specified awgn + shot file of 40 inputs x 8 shots with taps: shot
    lowered the held-out discrepancy by 1.8 sd where a parameter must buy 2, while the
    variance's test against the signal rejected awgn at Holm-adjusted p = 9e-5): there the
    effect buys its keep when its own campaigns show what the identification found.

    The identification is run on :data:`REPLICATES` campaigns of the candidate's own shots
    (the measurement's inputs, times and r; keys named by the effects), and each test that
    names a class at Holm-adjusted 0.01 on the measurement is read off each: its measured z
    against their mean and spread, (z - mean) / (sd sqrt(1 + 1/R)). A test's z is a statistic
    standardised over the inputs, whose spread over campaigns is about 1 whatever the model
    (0.59 on shot's and multiplicative's campaigns of the small file above, 0.82-1.03 on
    common_mode's, awgn's and laplace's); a spread that R campaigns put below 1 is taken as 1
    and the ratio read as normal, a larger one as Student's t with R - 1 degrees of freedom, so
    a right model's lucky small spread does not refuse it. With 8 campaigns a wrong model's
    wide spread passed it (laplace's -0.48 +- 1.34 against the measured 4.68, t with 7 degrees
    of freedom); with 16, -0.43 +- 1.03 refuses it (p = 0.00045). It
    reproduces what was found when no test's two-sided p, Bonferroni over the tests, is below
    0.01 -- every finding, of every class (a finding the candidate has no term for is one it
    does not reproduce). The baseline's own campaigns are read the same way: a candidate buys
    nothing where they reproduce it too. The campaigns are drawn in two stages of R / 2 (in the
    lab's threads): the first refuses where a test is not made on one of them, or where p on
    their own spread is below :data:`EARLY` -- then the second half is not drawn.

    Each test's z is read with the sign of its effect (:func:`_signed`): a test's z is its
    deviation's size, and a law with lighter tails than the Gaussian's deviates as far from it as
    one with heavier tails.

    ``check(c)`` returns ``(reproduced, sentence)``; the sentence says the worst test either way."""
    base_cmp = session.baseline_comparison
    rows = [r for r in ([] if ident is None else ident.rows()) if named(r, ident.taps)]
    if not rows or base_cmp.p_value < ALPHA:
        return None
    meas, r = session.meas, session.meas.r
    keys = [_key(r_) for r_ in rows]
    zd = np.array([_signed(r_) for r_ in rows])
    m = len(rows)

    threads = default_workers(meas)

    def pair(model, name, j):
        """The signed z of the tests on the model's campaigns 2 j and 2 j + 1 (one draw of 2 r
        shots, the fit's compiled shape; NaN where a campaign does not make a test)."""
        own = model_shots(named_subkey(session.k_cmp, f"found/{name}/{j}"), model, meas, 2 * r)
        out = np.full((2, m), np.nan)
        for h in range(2):
            part = [np.asarray(a[:, h * r:(h + 1) * r], np.float64) for a in own]
            sim = dataclasses.replace(meas, y=part[-1], taps=tuple(part[:-1]) if meas.has_taps else None)
            got = {_key(g): _signed(g) for g in identify(sim, output_candidates=False).rows()}
            out[h] = [got.get(k, np.nan) for k in keys]
        return out

    def campaigns(model, name):
        """The tests on the model's campaigns (pure, keyed work, in the lab's threads), in two
        stages: the first :data:`REPLICATES` / 2 campaigns, and the rest only where those do not
        already refuse it (a test not made, or p below :data:`EARLY` on their own spread); then
        the worst test as :func:`worst` reads it."""
        with one_blas_thread():  # entered once around the campaigns' threads
            z = np.concatenate(map_in_threads(lambda j: pair(model, name, j), range(REPLICATES // 4), threads))
            first = worst(z)
            p, missing = first[0], first[4]
            if missing or p < EARLY:
                return first
            z = np.concatenate([z] + map_in_threads(lambda j: pair(model, name, j),
                                                    range(REPLICATES // 4, REPLICATES // 2), threads))
        return worst(z)

    def worst(z):
        R = len(z)
        missing = np.isnan(z).sum(0)  # a test some campaigns do not make (a layer of no one level) is not reproduced
        with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)  # a column all NaN: its mean is NaN
            mean, sd = np.nanmean(z, 0), np.nanstd(z, 0, ddof=1)
            t = (zd - mean) / (np.maximum(sd, 1.0) * np.sqrt(1.0 + 1.0 / R))
            tail = np.where(sd > 1.0, 2.0 * stats.t.sf(np.abs(t), R - 1), 2.0 * stats.norm.sf(np.abs(t)))
        p = np.where((missing == 0) & np.isfinite(t), np.minimum(1.0, m * tail), 0.0)
        i = int(np.argmin(p))
        return float(p[i]), i, float(mean[i]), float(sd[i]), int(missing[i]), R

    base = []

    def check(c):
        name = " + ".join(c.effects)
        p, i, mean, sd, missing, drawn = campaigns(c.model, "+".join(c.effects))
        if p >= ALPHA and not base:  # the baseline's campaigns: only where the candidate's reproduce it all
            base.append(campaigns(session.baseline, "awgn"))
        cls, test, layer = keys[i]
        said = (f"{cls}'s {test} test " + (f"at layer {layer}" if layer else "across the layers")
                + f": z = {zd[i]:.2f} measured (signed by its effect), "
                + (f"not made on {missing} of the {drawn} campaigns of its own shots drawn" if missing else
                   f"{mean:.2f} +- {sd:.2f} on {drawn} campaigns of its own shots (p = {p:.2g}"
                   + (f"; the baseline's p = {base[0][0]:.2g})" if base else ")")))
        if p >= ALPHA and base[0][0] < ALPHA:
            return True, (f"awgn + {name} buys its keep where the identification looked: its own campaigns "
                          f"reproduce every test that rejects awgn, the worst {said}")
        return False, f"awgn + {name}'s own campaigns do not reproduce what the identification found: {said}"

    return check


def first_refusal(*checks):
    """The first reason any of ``checks`` (each None or ``check(c) -> reason | None``) gives."""
    live = [c for c in checks if c is not None]
    if not live:
        return None

    def check(c):
        for ch in live:
            why = ch(c)
            if why:
                return why
        return None

    return check


@dataclasses.dataclass(frozen=True)
class _Found:
    """What the identification names (Holm-adjusted 0.01), as the rules below read it."""

    rows: list
    output_candidates: tuple
    trend: list
    memory: list
    lag_ran: bool
    baseline_passes: bool
    flagged: list
    base_cmp: object


def refuse_untimed_under_a_trend(c, found: _Found):
    """A trend in acquisition time (a time_drift test): the held-out test compares per-input
    means, which average an interleaved acquisition's trend away (a bias drift passed as
    layer_gain without taps, a gain drift as activation_gain). Refused: a candidate with no effect
    that acts through the times (other than a memory)."""
    if found.trend and not any(REGISTRY[e].needs_times and REGISTRY[e].mechanism != "memory" for e in c.effects):
        return (f"the identification finds a trend in acquisition time (time_drift {_where(found.trend)}) that "
                f"awgn + {' + '.join(c.effects)} has no term for: its held-out test compares per-input means, which "
                f"average the trend away"), True
    return None


def refuse_a_memory_not_found(c, found: _Found):
    """A candidate with a memory where the lag test (it ran) names none: a memory's shift and excess
    variance of each neuron are what other physics gives too."""
    if not found.memory and found.lag_ran and any(REGISTRY[e].mechanism == "memory" for e in c.effects):
        return (f"awgn + {' + '.join(c.effects)} has a memory the identification does not find (its lag test names "
                f"no layer at Holm-adjusted 0.01): through each input's shots a memory is a shift and an excess "
                f"variance of each neuron, which other physics gives too"), False
    return None


def refuse_no_memory_where_found(c, found: _Found):
    """The shots carry the shot acquired before them (the memory class's lag test): the held-out
    test compares each input's shots, whatever order they were taken in (a detector's memory
    passed as bias offsets). Refused: a candidate with no effect of class memory."""
    if found.memory and not any(REGISTRY[e].mechanism == "memory" for e in c.effects):
        return (f"the identification finds that the shots carry the shot acquired before them (memory "
                f"{_where(found.memory)}), which awgn + {' + '.join(c.effects)} has no term for: its held-out test "
                f"compares each input's shots, not the order they were taken in"), True
    return None


def refuse_where_the_output_means_disagree(c, found: _Found):
    """Without taps: the candidate mechanisms put into the model (:mod:`._explain_output`) say its
    class does not reproduce the output's mean while another class does
    (:func:`~gift_theory.lab._explain_output.mean_refusal`): the detectors' gain and offset passed
    as layer_gain (p = 0.22) while no gain put into the model fitted every input's mean and each
    output neuron's own gain and offset did."""
    why = mean_refusal(mechanism_classes("+".join(c.effects)), found.output_candidates) \
        if found.output_candidates else None
    return (f"awgn + {' + '.join(c.effects)}: {why}", True) if why else None


def refuse_what_the_held_out_test_cannot_see(c, found: _Found):
    """Any class, when the baseline itself passes its held-out test: that test has no power against
    what the identification finds (Student-t noise in one layer of a tapped chip passed as awgn at
    p = 0.40 while the kurtosis test rejected awgn with z = 10.7). Refused: a candidate with no
    effect of a flagged class."""
    if found.baseline_passes and found.flagged and not mechanism_classes("+".join(c.effects)) & set(found.flagged):
        what = "; ".join(f"{k} {_where([r for r in found.rows if r['class'] == k])}" for k in found.flagged)
        return (f"the identification finds {what}, which awgn + {' + '.join(c.effects)} has no term for; the "
                f"held-out test does not see it (the awgn model passes that test too, p = "
                f"{found.base_cmp.p_value:.3g})"), True
    return None


#: the rules of the identification, in the order they are asked (the first that refuses is said)
IDENTIFICATION_RULES = (refuse_untimed_under_a_trend, refuse_a_memory_not_found, refuse_no_memory_where_found,
                        refuse_where_the_output_means_disagree, refuse_what_the_held_out_test_cannot_see)


def identification_refusals(cands: list, ident, base_cmp=None, shots_rule=None, found_rule=None) -> list:
    """A candidate that passes its held-out test is refused when the identification finds
    (:func:`~gift_theory.lab._mechanisms.named`: Holm-adjusted 0.01) something that test cannot see
    and the candidate has no term for: each of :data:`IDENTIFICATION_RULES`, then ``shots_rule``
    (:func:`unmoved_tails_rule` and :func:`unreproduced_correlations_rule`, composed by
    :func:`first_refusal`): a candidate whose own shots' tails, or correlations, differ from the
    measured ones and have not moved towards them from the baseline's.

    Before them, ``found_rule`` (:func:`found_reproduced_rule`) is asked of a candidate with an
    effect of a class the identification names that was refused only because it does not buy
    its keep on the held-out half: where its own campaigns reproduce what the identification
    found, it buys its keep there (``bought_by``) and passes on to these rules.

    Each refusal here but a memory not found marks the candidate ``lacks``: when none passes, the
    greedy second step builds on it."""
    if ident is None:
        return cands
    rows = [r for r in ident.rows() if named(r, ident.taps)]
    found = _Found(rows, getattr(ident, "output_candidates", ()) if not ident.taps else (),
                   [r for r in rows if r["class"] == "time_drift"], [r for r in rows if r["class"] == "memory"],
                   any(r["class"] == "memory" and r["test"] == "lag" for r in ident.rows()),
                   base_cmp is not None and base_cmp.p_value >= ALPHA, sorted({r["class"] for r in rows}), base_cmp)
    out = []
    for c in cands:
        # only an effect of a class the identification names can buy its keep there: any other
        # is refused below (what the held-out test cannot see), and each check runs the
        # identification on up to 16 campaigns (without taps a second or more each)
        if (found_rule is not None and c.status == "refused" and base_cmp is not None
                and mechanism_classes(c.name) & set(found.flagged)
                and c.refused_for == ("keep",)):
            bought, why = found_rule(c)
            c = (dataclasses.replace(c, status="passes", refused_because=(), refused_for=(), bought_by=why) if bought
                 else _refuse(c, why, "not_reproduced", lacks=c.lacks))
        for rule in IDENTIFICATION_RULES:
            hit = rule(c, found) if c.status == "passes" else None
            if hit:
                c = _refuse(c, hit[0], rule.__name__, lacks=hit[1])
        why = shots_rule(c) if c.status == "passes" and shots_rule is not None else None
        if why:
            c = _refuse(c, why, "shots", lacks=True)
        out.append(c)
    return out
