"""The lab's pipeline: which effect is missing, or -- when none it knows explains the data -- where to look.

One :func:`diagnose` reads top-down as the stages of the lab::

    split the inputs        (fit half, held-out half)                         this module
    model shots             (the core's sampler and forward pass)             ._shots
    fit a model             (moments, offsets, values read off the data)      ._fit
    score its discrepancy   (channels, the Q-test, the noise floor)           ._compare
    localise                (one-step check per layer, residual profiles)     ._localise
    name mechanisms         (rules from the localised evidence)               ._mechanisms
    verdict                 (explained? what remains, where to look)          ._verdict

The baseline (awgn, s fitted) and every candidate ``awgn + effect`` (every registered effect
by default: the built-in ones and any plugin) are fitted on the fitting half and scored on
the held-out half. Candidates are ranked by ``discrepancy_after + 2 sd * (parameters the
effect adds)`` -- sd the baseline's standard deviation of the discrepancy under the model, a
per-device offset family counted by its effective degrees of freedom -- so a one-parameter
effect that explains the data beats a many-parameter one that also does (CONTRACTS §4); a
candidate that passes its test ranks before every one that fails (:func:`rank_key`).
``missing_effect_detected`` is the baseline's goodness-of-fit test, ``p_value < 0.01``.
A model with fitted offsets is tested against a refit null (:mod:`._fit_offsets`).
"""

from __future__ import annotations

import concurrent.futures
import contextvars
import dataclasses
import os
import sys
import time

import jax
import numpy as np

from .._errors import GiftInputError
from .._measurement import Measurement
from ..effects import BUILTIN, REGISTRY
from ._channels import Reference, channel_values, reference
from ._compare import Comparison, compare, failing_layers, one_step_check
from ._fit import fit_model
from ._fit_moments import MomentProblem
from ._fit_offsets import effective_dof, fitted_as_offsets, kinds_of, offset_replicates, prior_check
from ._localise import (
    layer_evidence,
    one_step_residuals,
    residuals,
    signatures,
    where_it_fails,
)
from ._mechanisms import Context, fit_gains, mechanisms
from ._shots import Model
from ._verdict import as_json_fields, verdict

#: the significance level of the goodness-of-fit test (CONTRACTS §4)
ALPHA = 0.01
#: with taps, an offset model whose plain held-out test gives p below this is not run against
#: its refit null (:meth:`Session.score`)
REFIT_SKIP_P = 1e-30


def split_inputs(key, n: int, frac: float = 0.5):
    """Random disjoint (fit, held-out) index arrays over ``n`` inputs."""
    if n < 4:
        raise GiftInputError(f"measurement has {n} inputs; fitting and held-out scoring need at least 4")
    perm = np.asarray(jax.random.permutation(key, n))
    k = n - int(round(n * (1 - frac)))  # held-out half n // 2 (equal halves share compiled shapes)
    k = min(max(k, 2), n - 2)
    return np.sort(perm[:k]), np.sort(perm[k:])


def default_candidates(meas: Measurement) -> list[str]:
    """Every registered effect a diagnosis of ``meas`` tries: all but awgn, and those silent
    without acquisition times only when the file has them."""
    names = list(BUILTIN) + [n for n in REGISTRY if n not in BUILTIN]  # catalogue order, then plugins
    return [n for n in names if n != "awgn" and (meas.t is not None or not REGISTRY[n].needs_times)]


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One fitted extension of the model, scored on held-out inputs.

    n_free : the parameters it adds, an offset family counted by its effective degrees of freedom
    nominal : the parameters it adds, every offset counted as one
    """

    effects: tuple
    model: Model
    comparison: Comparison
    score: float
    seconds: float
    n_free: float = 0.0
    nominal: int = 0

    def mechanism(self) -> str:
        return "+".join(REGISTRY[e].mechanism for e in self.effects)

    def as_json(self) -> dict:
        # a second-stage entry is named by the effect it adds; "with" lists the ones before
        out = {"effect": self.effects[-1], "mechanism": self.mechanism(),
               "discrepancy_after": self.comparison.discrepancy, "p_value_after": self.comparison.p_value,
               "params": self.model.params_json(), "se": self.comparison.se, "score": self.score,
               "n_free": self.n_free, "nominal_params": self.nominal}
        if len(self.effects) > 1:
            out["with"] = list(self.effects[:-1])
        if self.comparison.replicates:
            out["net_discrepancy_after"] = self.comparison.net_discrepancy
            out["refit_null_replicates"] = self.comparison.replicates
        return out


def _log(msg, verbose):
    if verbose:
        sys.stderr.write(msg + "\n")
        sys.stderr.flush()


def penalised_score(cmp: Comparison, n_params: float, base: Comparison | None = None) -> float:
    """Held-out discrepancy plus 2 standard deviations per added parameter. The unit is the
    baseline's standard deviation of Q under the model (one scale for every candidate; a
    candidate's own would reward a model whose channels happen to be more correlated)."""
    unit = base.se if base is not None and base.se > 0 else cmp.se
    return float(cmp.discrepancy + 2.0 * unit * n_params)


class Session:
    """What every model scored on one measurement shares: the split of its inputs, the held-out
    half's :class:`Reference`, the fitting half's moments, the refit null of offset models and
    the baseline. Built once by :func:`diagnose`, :func:`fit_effects` and
    :func:`compare_measurement` from the same named subkeys, so their numbers agree."""

    def __init__(self, key, meas: Measurement, shots: int | None = None, workers: int | None = None):
        self.meas, self.shots = meas, shots
        # threads for the refit nulls' replicates and the candidates (the numbers do not depend on it)
        self.workers = default_workers() if workers is None else max(1, int(workers))
        k_split, self.k_fit, self.k_cmp, k_ref, self.k_step = jax.random.split(key, 5)
        self.train, self.test = split_inputs(k_split, meas.n)
        self.fit_meas, self.test_meas = meas.subset(self.train), meas.subset(self.test)
        self.ref: Reference = reference(k_ref, self.test_meas)
        self.problem = MomentProblem(self.k_fit, self.fit_meas, shots)
        self._replicates, self._priors = {}, {}
        self.baseline: Model | None = None  # fit() reads it: offsets fitted from scratch start from it
        self.baseline = self.fit(())
        self.baseline_comparison = self.score(self.baseline)

    def fit(self, effects, start: Model | None = None) -> Model:
        return fit_model(self.k_fit, self.fit_meas, effects, start=start, K=self.shots, problem=self.problem,
                         baseline=self.baseline)

    def prior(self, model: Model) -> list:
        """:func:`~gift_theory.lab._fit_offsets.prior_check` of a fitted model on the fitting
        half, made once per model (the mechanisms' fit gains and the verdict both read it)."""
        if id(model) not in self._priors:
            self._priors[id(model)] = (model, prior_check(model, self.fit_meas))
        return self._priors[id(model)][1]

    def score(self, model: Model, plain: Comparison | None = None, held_out: Measurement | None = None) -> Comparison:
        """The held-out comparison; a model with fitted offsets against its refit null (made once
        per set of offset effects and reused). With taps, a model whose plain test already
        rejects at :data:`REFIT_SKIP_P` skips the refit null: there the offsets are identified and
        their estimation error shifts the discrepancy by a few of its standard deviations
        (measured: 5.5 on docs/lab.md's weight_error example), far less than such a rejection
        needs (some 30). ``plain``: the model's plain comparison, if already made.

        The refit nulls are numbered in the order they are first needed, so models must be
        scored in a fixed order (:meth:`candidates` does); the rest is safe to run in threads.

        ``held_out``: a variant of the held-out half with the same data (the verdict's time-free
        twin holds the acquisition times at their mean), scored against the same reference."""
        names = tuple(sorted(n for n in model.offsets if fitted_as_offsets(n)))
        test_meas = self.test_meas if held_out is None else held_out
        if plain is None:
            plain = compare(self.k_cmp, model, test_meas, shots=self.shots, ref=self.ref)
        if not names or (self.meas.has_taps and plain.p_value < REFIT_SKIP_P):
            return plain
        if names not in self._replicates:
            self._replicates[names] = offset_replicates(
                jax.random.fold_in(self.k_cmp, len(self._replicates)), model, self.fit_meas, self.test_meas,
                self.ref, channel_values=channel_values, shots=self.shots, workers=self.workers)
        return compare(self.k_cmp, model, test_meas, shots=self.shots, ref=self.ref,
                       null_replicates=self._replicates[names])

    def _prepare(self, start, fit_names, added):
        """The order-free part of a candidate (fit, plain comparison, parameter count): pure."""
        t0 = time.time()
        model = self.fit(fit_names, start=start)
        plain = compare(self.k_cmp, model, self.test_meas, shots=self.shots, ref=self.ref)
        n_free, nominal = 0.0, 0
        for name in added:
            if fitted_as_offsets(name):
                dof, nom = effective_dof(self.k_fit, self.fit_meas, model, kinds_of([name], self.meas.arch))
                n_free, nominal = n_free + dof, nominal + nom
            else:
                n_free, nominal = n_free + len(REGISTRY[name].params), nominal + len(REGISTRY[name].params)
        return model, plain, n_free, nominal, time.time() - t0

    def candidates(self, requests) -> list:
        """Fit and score ``requests`` in order: (effects, start model or None, the effects to fit
        on top of it, the effects whose parameters the candidate is charged for), ...

        The fits and plain comparisons are independent, so the session's ``workers`` threads run
        them at once (JAX's programs and numpy's sorts run without the GIL); the refit nulls are
        then made in the order of ``requests``. Same numbers for any number of threads."""
        requests = list(requests)
        if self.workers > 1 and len(requests) > 1:
            with concurrent.futures.ThreadPoolExecutor(max_workers=self.workers) as pool:
                # each task in a copy of this context, so a PhaseClock still sees its compiles
                futs = [pool.submit(contextvars.copy_context().run, self._prepare, *r[1:]) for r in requests]
                prepared = [f.result() for f in futs]
        else:
            prepared = [self._prepare(*r[1:]) for r in requests]
        out = []
        for (effects, *_), (model, plain, n_free, nominal, seconds) in zip(requests, prepared):
            t0 = time.time()
            cmp = self.score(model, plain)
            score = penalised_score(cmp, n_free, self.baseline_comparison)
            out.append(Candidate(tuple(effects), model, cmp, score, seconds + time.time() - t0, float(n_free),
                                 int(nominal)))
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
    has_taps: bool = False
    signatures: dict = dataclasses.field(default_factory=dict)
    where: dict | None = None
    explained: bool = False
    reasons: tuple = ()
    verdict: str = ""
    failing_layers: tuple | None = None
    mechanisms: tuple = ()
    evidence: tuple = ()

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
                **as_json_fields(self.explained, self.reasons, self.verdict, self.failing_layers, self.mechanisms),
                "ranking": [cand.as_json() for cand in self.ranking],
                "evidence": list(self.evidence),
                "where": list(self.one_step),
                "signatures": self.signatures,
                "worst_cells": [] if self.where is None else self.where["worst"][:10],
                "held_out_inputs": int(len(self.held_out)),
                **({"refit_null_calibrated": self.has_taps} if any(c.comparison.replicates for c in self.ranking)
                   else {}),
                "seconds": self.seconds}


def rank_key(c: Candidate):
    """Candidates that pass their test (p >= 0.01) come first, each group by penalised score: a
    model that fits is an answer, one that fails is not, whatever parameters it spends (a
    per-device offset family with its hundreds of effective parameters must not lose to a
    one-parameter effect that leaves the data unexplained)."""
    return (c.comparison.p_value < ALPHA, c.score)


def _improves(pair: Candidate, first: Candidate) -> bool:
    """A pair replaces its first effect at the top only if it passes the test and ranks before
    it (:func:`rank_key`): a failing pair is not an answer (measured: fitted weight offsets
    that still fail were "improved" by a 1 % drift gain)."""
    return pair.comparison.p_value >= ALPHA and rank_key(pair) < rank_key(first)


def _merge_second_stage(first: Candidate, stage2: list, singles: list) -> list:
    """The ranking after the greedy second step: the best pair that improves on the first
    effect (:func:`_improves`), the first effect itself right after it (the path that led
    there), the other improving pairs, then everything else by penalised score. A runner-up
    tried on top of the first is listed as the pair only."""
    better = sorted((c for c in stage2 if _improves(c, first)), key=rank_key)
    named = {c.effects[-1] for c in stage2}
    rest = sorted([c for c in stage2 if not any(c is b for b in better)] + [c for c in singles if c.effects[0] not in named],
                  key=rank_key)
    return better[:1] + [first] + better[1:] + rest


def _compatible(first: Candidate, name: str) -> bool:
    """``name`` can be added on top of ``first``: not already there, not a second noise law."""
    if name in first.effects:
        return False
    laws = [e for e in first.effects if REGISTRY[e].stage == "law"]
    return not (laws and REGISTRY[name].stage == "law")


def _check_candidates(names, meas: Measurement) -> list:
    for c in names:
        for e in c.split("+"):
            if e not in REGISTRY or e == "awgn":
                raise GiftInputError(f"--candidates: unknown effect {e!r}; known: "
                                     f"{', '.join(n for n in REGISTRY if n != 'awgn')}")
            if REGISTRY[e].needs_times and meas.t is None:
                raise GiftInputError(f"--candidates {e}: needs acquisition times t in the measurement")
    return list(names)


#: runners-up fitted on top of a failing first effect (the greedy second step)
SECOND = 4


def _rank(session: Session, names, second, verbose: bool) -> list:
    """Every candidate fitted and scored, ranked; a second stage on top of the best one when it
    still fails (see :func:`diagnose`)."""
    singles = [tuple(n.split("+")) for n in names]
    ranking = session.candidates([(effects, None, effects, effects) for effects in singles])
    for name, cand in zip(names, ranking):
        _log(f"  + {name:<15s} {cand.model.describe():<60s} discrepancy {cand.comparison.discrepancy:.3g} "
             f"p = {cand.comparison.p_value:.3g} ({cand.seconds:.1f} s)", verbose)
    ranking.sort(key=rank_key)
    if second != 0 and ranking and ranking[0].comparison.p_value < ALPHA and len(ranking) > 1:
        first = ranking[0]
        rest = [c.effects[0] for c in ranking[1:] if _compatible(first, c.effects[0])][:second]
        stage2 = session.candidates([(first.effects + (name,), first.model, (name,), first.effects + (name,))
                                     for name in rest])
        for cand in stage2:
            _log(f"  + {'+'.join(cand.effects):<30s} {cand.model.describe():<60s} discrepancy "
                 f"{cand.comparison.discrepancy:.3g} p = {cand.comparison.p_value:.3g}", verbose)
        ranking = _merge_second_stage(first, stage2, ranking[1:])
    return ranking


def _localise(session: Session, base: Model, meas: Measurement, shots):
    """Where the baseline fails, each layer on its own: the one-step checks (with taps), the
    failing layers, the layer evidence, the signatures and where-it-fails (pure: keyed by
    the session's step key)."""
    taps = meas.has_taps
    steps = tuple(one_step_check(session.k_step, base, meas)) if taps else ()
    failing = failing_layers(steps) if taps else None
    res = residuals(session.k_step, base, meas, shots)
    local = one_step_residuals(session.k_step, base, meas, {r["layer"]: r["s"] for r in steps}) if taps else res
    evidence = layer_evidence(local)
    sigs, where = signatures(session.k_step, base, meas, res=res), where_it_fails(session.k_step, base, meas, res=res)
    return steps, failing, evidence, sigs, where


def default_workers() -> int:
    """Threads for the candidates: the cores this process may use, at most 4 (``$GIFT_LAB_THREADS``)."""
    env = os.environ.get("GIFT_LAB_THREADS", "").strip()
    if env.isdigit() and int(env) >= 1:
        return int(env)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return max(1, min(4, cores))


def diagnose(key, meas: Measurement, *, candidates=None, shots: int | None = None, second: int | None = SECOND,
             verbose: bool = False, workers: int | None = None) -> Diagnosis:
    """Fit the baseline and every candidate effect; rank them on held-out inputs.

    Parameters
    ----------
    key : PRNG key (split into ``split``, ``fit``, ``compare``, ``floor``, ``step`` subkeys)
    meas : Measurement
    candidates : effect names to try (default :func:`default_candidates`: every registered effect but
        awgn; those that need acquisition times only when the file has them)
    shots : model shots per input (default 4 r)
    second : when the best single effect still fails (p < 0.01), the best ``second``
        runners-up (default 4; None: all) are each fitted on top of it (a greedy forward step,
        for two missing effects) and ranked with the rest
    workers : threads fitting the candidates at once (default :func:`default_workers`); the
        numbers do not depend on it

    Returns
    -------
    Diagnosis
    """
    t0 = time.time()
    names = default_candidates(meas) if candidates is None else _check_candidates(candidates, meas)
    session = Session(key, meas, shots, workers)
    base, base_cmp = session.baseline, session.baseline_comparison
    _log(f"baseline {base.describe()}: discrepancy {base_cmp.discrepancy:.3g} +- {base_cmp.se:.2g} "
         f"(floor {session.ref.noise_floor:.3g}), p = {base_cmp.p_value:.3g}", verbose)
    # localising needs only the baseline: with threads to spare it runs beside the candidates
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as side:
        local = (side.submit(contextvars.copy_context().run, _localise, session, base, meas, shots)
                 if session.workers > 1 else None)
        ranking = _rank(session, names, second, verbose)
        steps, failing, evidence, sigs, where = (local.result() if local is not None
                                                 else _localise(session, base, meas, shots))
    taps = meas.has_taps
    # name mechanisms, then the verdict
    ctx = Context({row["layer"]: row for row in evidence}, meas.arch.depth, taps, failing,
                  fit_gains(ranking, base_cmp, session.prior), {r["layer"]: (r["s"], r["level_z"]) for r in steps})
    mechs = mechanisms(ctx)
    explained, reasons, line = verdict(session, ranking, meas, mechs, failing)
    _log(line, verbose)
    return Diagnosis(base, base_cmp, tuple(ranking), steps, session.test, time.time() - t0, taps, sigs, where,
                     explained, tuple(reasons), line, None if failing is None else tuple(failing), tuple(mechs),
                     tuple(evidence))


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of :func:`fit_effects`: the model before and after adding effects."""

    before: Model
    after: Model
    comparison_before: Comparison
    comparison_after: Comparison
    ladder: tuple  # ((label, Comparison), ...) one rung per added effect
    has_taps: bool = False

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
                **({"net_discrepancy_after": a.net_discrepancy, "refit_null_replicates": a.replicates,
                    "refit_null_calibrated": self.has_taps} if a.replicates else {})}


def fit_effects(key, meas: Measurement, effects, *, shots: int | None = None, verbose: bool = False) -> FitResult:
    """Add ``effects`` to the awgn model one at a time, fit on half the inputs, score the
    other half: the error ladder awgn -> +effect -> +effect.

    Parameters
    ----------
    key : PRNG key (the same subkeys as :func:`diagnose`, so the numbers agree)
    meas : Measurement
    effects : names of registered effects to add
    """
    effects = [e for e in effects if e != "awgn"]
    for e in effects:
        if effects.count(e) > 1:
            raise GiftInputError(f"--add {e} given twice")
        if e not in REGISTRY:
            raise GiftInputError(f"--add: unknown effect {e!r}; known: {', '.join(REGISTRY)}")
        if REGISTRY[e].needs_times and meas.t is None:
            raise GiftInputError(f"--add {e}: the measurement has no acquisition times t; {e} is silent without them")
    session = Session(key, meas, shots)
    base, base_cmp = session.baseline, session.baseline_comparison
    ladder = [("awgn", base_cmp)]
    _log(f"awgn: {base.describe()} discrepancy {base_cmp.discrepancy:.3g} (floor {session.ref.noise_floor:.3g})",
         verbose)
    model, cmp, added = base, base_cmp, []
    for e in effects:
        added.append(e)
        model = session.fit((e,), start=model)
        cmp = session.score(model)
        ladder.append(("awgn + " + " + ".join(added), cmp))
        _log(f"+{e}: {model.describe()} discrepancy {cmp.discrepancy:.3g} p = {cmp.p_value:.3g}", verbose)
    return FitResult(base, model, base_cmp, cmp, tuple(ladder), meas.has_taps)


def compare_measurement(key, meas: Measurement, physics=None, *, shots: int | None = None) -> dict:
    """``gift compare``: the awgn model fitted on half the inputs and scored on the other half
    (the same subkeys as :func:`diagnose`), or -- given ``physics`` -- exactly that model scored
    on every input; plus the one-step check per layer when the file has taps.

    Returns
    -------
    {"model": Model, "fitted": bool, "comparison": Comparison, "scored": Measurement,
     "where": [one-step rows]}
    """
    if physics is None:
        session = Session(key, meas, shots)
        model, cmp, scored, fitted = session.baseline, session.baseline_comparison, session.test_meas, True
        k_step = session.k_step
    else:
        _, _, k_cmp, k_ref, k_step = jax.random.split(key, 5)
        model, scored, fitted = Model(physics), meas, False
        cmp = compare(k_cmp, model, meas, shots=shots, ref=reference(k_ref, meas))
    where = one_step_check(k_step, model, meas) if meas.has_taps else []
    return {"model": model, "fitted": fitted, "comparison": cmp, "scored": scored, "where": where}
