"""Which effect is missing: fit every candidate extension, rank by held-out discrepancy.

The inputs are split at random into a fitting half and a held-out half. The baseline
(awgn, s fitted) and every candidate ``awgn + effect`` are fitted on the first half and
scored on the second with :func:`gift_theory.lab.compare`. Candidates are ranked by
``discrepancy_after + 2 sd * (number of parameters the effect adds)``, sd the baseline's
standard deviation of the discrepancy under the model: an extra parameter must buy two
standard deviations of held-out discrepancy, so a one-parameter effect that explains the
data beats a many-parameter one that also does (CONTRACTS §4).
``missing_effect_detected`` is the baseline's goodness-of-fit test, ``p_value < 0.01``.

A model with fitted weight offsets has hundreds of parameters; their estimation error is
part of its held-out discrepancy (so ranking charges it for them), but its p-value is taken
against a refit null (:func:`gift_theory.lab._fit.offset_replicates`: B = 8 replicates of
simulate-refit-score), so that a correct offset model passes (measured with taps: 1/100
false alarms at 0.01; without taps most offsets are unidentified, the replicates' truths
are drawn from the offsets' posterior, and the refit null is closer but still
anti-conservative: 8/100, docs/lab.md section 6). The replicates are made once
per call, for the first candidate with offsets, and reused by the others that have them.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import jax
import numpy as np

from .._errors import GiftInputError
from ._compare import Comparison, Model, compare, one_step_check, reference
from ._fit import CANDIDATES, N_PARAMS, fit_model, offset_replicates, split_inputs
from ._measurement import Measurement

#: the significance level of the goodness-of-fit test (CONTRACTS §4)
ALPHA = 0.01


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One fitted extension of the model, scored on held-out inputs."""

    effects: tuple
    model: Model
    comparison: Comparison
    score: float
    seconds: float

    def as_json(self) -> dict:
        # a second-stage entry is named by the effect it adds; "with" lists the ones before
        out = {"effect": self.effects[-1], "discrepancy_after": self.comparison.discrepancy,
                "p_value_after": self.comparison.p_value, "params": self.model.params_json(),
                "se": self.comparison.se, "score": self.score}
        if len(self.effects) > 1:
            out["with"] = list(self.effects[:-1])
        if self.comparison.replicates:
            out["net_discrepancy_after"] = self.comparison.net_discrepancy
            out["refit_null_replicates"] = self.comparison.replicates
        return out


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`."""

    baseline: Model
    baseline_comparison: Comparison
    ranking: tuple
    one_step: tuple
    held_out: np.ndarray
    seconds: float

    @property
    def missing_effect_detected(self) -> bool:
        return bool(self.baseline_comparison.p_value < ALPHA)

    def as_json(self) -> dict:
        """The CONTRACTS §4 object of ``gift diagnose --json`` (plus a few extra keys)."""
        c = self.baseline_comparison
        return {"baseline": {"effects": self.baseline.effects, "params": self.baseline.params_json(),
                             "discrepancy": c.discrepancy, "noise_floor": c.noise_floor, "p_value": c.p_value,
                             "se": c.se, "floor_se": c.floor_se, "channel_z": c.as_dict()["channel_z"]},
                "missing_effect_detected": self.missing_effect_detected,
                "ranking": [cand.as_json() for cand in self.ranking],
                "where": list(self.one_step),
                "held_out_inputs": int(len(self.held_out)),
                "seconds": self.seconds}


def _log(msg, verbose):
    if verbose:
        sys.stderr.write(msg + "\n")
        sys.stderr.flush()


def penalised_score(cmp: Comparison, n_params: int, base: Comparison | None = None) -> float:
    """Held-out discrepancy plus 2 standard deviations per added parameter. The unit is the
    baseline's standard deviation of Q under the model (one scale for every candidate; a
    candidate's own would reward a model whose channels happen to be more correlated)."""
    unit = base.se if base is not None and base.se > 0 else cmp.se
    return float(cmp.discrepancy + 2.0 * unit * n_params)


def _improves(pair: Candidate, first: Candidate) -> bool:
    """A pair replaces its first effect at the top only if it beats its penalised score and
    passes the test: between two failing models the discrepancy's own noise (~ sqrt(4 Q))
    dwarfs the parsimony penalty, and a failing pair is not an answer (measured: fitted
    weight offsets that still fail were "improved" by a 1 % drift gain)."""
    return pair.score < first.score and pair.comparison.p_value >= ALPHA


class _Scorer:
    """Held-out scoring shared by every candidate of one call (refit null made once)."""

    def __init__(self, key, fit_meas, test_meas, ref, shots):
        self.key, self.fit_meas, self.test_meas, self.ref, self.shots = key, fit_meas, test_meas, ref, shots
        self.replicates = None

    def __call__(self, model: Model) -> Comparison:
        reps = None
        if model.params is not None and "weight_error" in model.extra:
            if self.replicates is None:
                self.replicates = offset_replicates(jax.random.fold_in(self.key, 4321), model, self.fit_meas,
                                                    self.test_meas, self.ref, shots=self.shots)
            reps = self.replicates
        return compare(self.key, model, self.test_meas, shots=self.shots, ref=self.ref, null_replicates=reps)


def _merge_second_stage(first: Candidate, stage2: list, singles: list) -> list:
    """The ranking after the greedy second step: the best pair that improves on the first
    effect (:func:`_improves`), the first effect itself right after it (the path that led
    there), the other improving pairs, then everything else by penalised score. A runner-up
    tried on top of the first is listed as the pair only."""
    better = sorted((c for c in stage2 if _improves(c, first)), key=lambda c: c.score)
    named = {c.effects[-1] for c in stage2}
    rest = sorted([c for c in stage2 if not any(c is b for b in better)] + [c for c in singles if c.effects[0] not in named],
                  key=lambda c: c.score)
    return better[:1] + [first] + better[1:] + rest


def diagnose(key, meas: Measurement, *, candidates=None, shots: int | None = None, second: int | None = None,
             verbose: bool = False) -> Diagnosis:
    """Fit the baseline and every candidate effect; rank them on held-out inputs.

    Parameters
    ----------
    key : PRNG key (split into ``split``, ``fit``, ``compare``, ``floor`` subkeys)
    meas : Measurement
    candidates : effect names to try (default: every CONTRACTS §2 effect except awgn;
        drift only when the file has acquisition times)
    shots : model shots per input (default 4 r)
    second : when the best single effect still fails (p < 0.01), the best ``second``
        runners-up (default: all; a strong first effect can push the second far down the
        single-effect list) are each fitted on top of it (a greedy forward step, for two
        missing effects) and ranked with the rest by penalised score; their entries carry
        both effects' parameters

    Returns
    -------
    Diagnosis
    """
    t0 = time.time()
    k_split, k_fit, k_cmp, k_ref, k_step = jax.random.split(key, 5)
    train, test = split_inputs(k_split, meas.n)
    mtr, mte = meas.subset(train), meas.subset(test)
    ref = reference(k_ref, mte)
    score_of = _Scorer(k_cmp, mtr, mte, ref, shots)
    base = fit_model(k_fit, mtr, (), K=shots)
    base_cmp = score_of(base)
    _log(f"baseline {base.describe()}: discrepancy {base_cmp.discrepancy:.3g} +- {base_cmp.se:.2g} "
         f"(floor {ref.noise_floor:.3g}), p = {base_cmp.p_value:.3g}", verbose)
    if candidates is None:
        candidates = [c for c in CANDIDATES if c != "drift" or meas.t is not None]
    ranking = []
    for name in candidates:
        if name == "drift" and meas.t is None:
            raise GiftInputError("candidate drift needs acquisition times t in the measurement")
        t1 = time.time()
        effects = tuple(name.split("+"))
        model = fit_model(k_fit, mtr, effects, start=base, K=shots)
        cmp = score_of(model)
        score = penalised_score(cmp, sum(N_PARAMS.get(e, 1) for e in effects), base_cmp)
        ranking.append(Candidate(effects, model, cmp, score, time.time() - t1))
        _log(f"  + {name:<15s} {model.describe():<60s} discrepancy {cmp.discrepancy:.3g} p = {cmp.p_value:.3g} "
             f"({time.time() - t1:.1f} s)", verbose)
    ranking.sort(key=lambda c: c.score)
    if second != 0 and ranking and ranking[0].comparison.p_value < ALPHA and len(ranking) > 1:
        # the best single effect still fails: add each runner-up on top of it (greedy forward step)
        first = ranking[0]
        laws = ("laplace", "uniform")
        has_law = any(e in laws for e in first.effects)
        rest = [c.effects[0] for c in ranking[1:] if c.effects[0] not in first.effects
                and not (has_law and c.effects[0] in laws)][:second]  # None: every runner-up
        stage2 = []
        for name in rest:
            t1 = time.time()
            effects = first.effects + (name,)
            model = fit_model(k_fit, mtr, (name,), start=first.model, K=shots)
            cmp = score_of(model)
            score = penalised_score(cmp, sum(N_PARAMS.get(e, 1) for e in effects), base_cmp)
            stage2.append(Candidate(effects, model, cmp, score, time.time() - t1))
            _log(f"  + {'+'.join(effects):<30s} {model.describe():<60s} discrepancy {cmp.discrepancy:.3g} "
                 f"p = {cmp.p_value:.3g}", verbose)
        ranking = _merge_second_stage(first, stage2, ranking[1:])
    steps = tuple(one_step_check(k_step, base, meas)) if meas.has_taps else ()
    return Diagnosis(base, base_cmp, tuple(ranking), steps, test, time.time() - t0)


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of :func:`fit_effects`: the model before and after adding effects."""

    before: Model
    after: Model
    comparison_before: Comparison
    comparison_after: Comparison
    ladder: tuple  # ((label, Comparison), ...) one rung per added effect

    def as_json(self) -> dict:
        """The CONTRACTS §4 object of ``gift fit --json`` (plus a few extra keys)."""
        a, b = self.comparison_after, self.comparison_before
        return {"effects": self.after.effects, "params": self.after.params_json(),
                "discrepancy_before": b.discrepancy, "discrepancy_after": a.discrepancy,
                "noise_floor": a.noise_floor, "p_value_after": a.p_value,
                "p_value_before": b.p_value, "se_before": b.se, "se_after": a.se, "floor_se": a.floor_se,
                "ladder": [{"model": lab, "discrepancy": c.discrepancy, "se": c.se, "p_value": c.p_value,
                            **({"net_discrepancy": c.net_discrepancy} if c.replicates else {})}
                           for lab, c in self.ladder],
                **({"net_discrepancy_after": a.net_discrepancy, "refit_null_replicates": a.replicates}
                   if a.replicates else {})}


def fit_effects(key, meas: Measurement, effects, *, shots: int | None = None, verbose: bool = False) -> FitResult:
    """Add ``effects`` to the awgn model one at a time, fit on half the inputs, score the
    other half: the error ladder awgn -> +effect -> +effect.

    Parameters
    ----------
    key : PRNG key (the same subkeys as :func:`diagnose`, so the numbers agree)
    meas : Measurement
    effects : names of CONTRACTS §2 effects to add
    """
    effects = [e for e in effects if e != "awgn"]
    for e in effects:
        if effects.count(e) > 1:
            raise GiftInputError(f"--add {e} given twice")
    k_split, k_fit, k_cmp, k_ref, _ = jax.random.split(key, 5)
    train, test = split_inputs(k_split, meas.n)
    mtr, mte = meas.subset(train), meas.subset(test)
    ref = reference(k_ref, mte)
    score_of = _Scorer(k_cmp, mtr, mte, ref, shots)
    base = fit_model(k_fit, mtr, (), K=shots)
    base_cmp = score_of(base)
    ladder = [("awgn", base_cmp)]
    _log(f"awgn: {base.describe()} discrepancy {base_cmp.discrepancy:.3g} (floor {ref.noise_floor:.3g})", verbose)
    model, cmp, added = base, base_cmp, []
    for e in effects:
        added.append(e)
        model = fit_model(k_fit, mtr, (e,), start=model, K=shots)
        cmp = score_of(model)
        ladder.append(("awgn + " + " + ".join(added), cmp))
        _log(f"+{e}: {model.describe()} discrepancy {cmp.discrepancy:.3g} p = {cmp.p_value:.3g}", verbose)
    return FitResult(base, model, base_cmp, cmp, tuple(ladder))
