"""The lab's pipeline: which effect is missing, or -- when none it knows explains the data -- where to look.

One :func:`diagnose` reads top-down as the stages of the lab::

    split the inputs        (fit half, held-out half)                         this module
    model shots             (the core's sampler and forward pass)             ._shots
    fit a model             (moments, offsets, values read off the data)      ._fit
    score its discrepancy   (channels, the Q-test, the noise floor)           ._compare
    check each that passes  (identified? its own effect? every layer?)        ._verdict
    localise                (one-step check per layer, residual profiles)     ._localise
    name mechanisms         (rules from the localised evidence)               ._mechanisms
    verdict                 (explained? what remains, where to look)          ._verdict

The baseline (awgn, s fitted) and every candidate ``awgn + effect`` (every registered effect
by default: the built-in ones and any plugin) are fitted on the fitting half and scored on
the held-out half. ``missing_effect_detected`` is the baseline's goodness-of-fit test,
``p_value < 0.01``. A model with fitted offsets is tested against a refit null
(:mod:`._offset_fit`, :mod:`._offset_null`).

**Status and order** (reference §6, 2026-11-25). Every candidate has a ``status``:
``"passes"`` (p >= 0.01 and every check of the verdict's rule holds: its values identified and
its own effect's, with taps every layer right, and it buys its keep -- :mod:`._verdict`),
``"refused"`` (p >= 0.01 but a check refuses it) or ``"fails"`` (p < 0.01). The ranking lists
those that pass, then the refused ones, then those the data reject (:func:`ranked`); among those
that pass by the penalised held-out discrepancy ``discrepancy_after + 2 sd * (parameters the
effect adds)`` (sd the baseline's standard deviation of the discrepancy, a per-device offset
family counted by its effective degrees of freedom: reference §4's parsimony, so a
one-parameter effect that explains the data beats a many-parameter one that also does), among
the refused and the rejected by the held-out discrepancy itself. So ranking[0] is the model the
verdict line names, and an effect the data reject at 0.01 is never first while another entry
passes or is refused.

**Which candidates are fitted.** The closed-form identification (:mod:`._identify`, every
class a test with a Holm-adjusted p-value) runs first. The candidates of the classes it flags
(a test rejecting at 0.01) are fitted first; when one of them passes every check, the others --
whose classes no test flags -- are not fitted and are listed under ``not_fitted`` with that
reason (an explanation has been found, and the data show nothing of their physics). When none
passes, every candidate is fitted, as if the identification had said nothing.

**Pure.** A :class:`Session` is immutable: what it computes for a model -- its refit null, the
checks of its fitted values -- depends on the model (its name and fitted values) and the
session's named subkeys only, never on what was scored before it or on how many threads
score at once; the memo that spares recomputing them is keyed by that content.
"""

from __future__ import annotations

import concurrent.futures
import contextvars
import dataclasses
import functools
import hashlib
import os
import sys
import threading
import time
import zlib

import jax
import numpy as np
from scipy import stats

from .._errors import GiftInputError
from .._measurement import Measurement
from ..effects import BUILTIN, REGISTRY
from ..effects._physics import scope_error
from .._model import named_subkey
from ._channels import Reference, channel_values, reference
from ._compare import Comparison, compare, failing_layers, one_step_check
from ._fit import fit_model
from ._fit_moments import MomentProblem
from ._offset_kinds import fitted_as_offsets, kinds_of
from ._offset_null import effective_dof, offset_replicates
from ._offset_prior import prior_check
from ._localise import (
    layer_evidence,
    one_step_residuals,
    residuals,
    signatures,
    where_it_fails,
)
from ._identify import _shots_law, _subset, _two_sided, identify
from ._budget import candidate_threads
from ._qtest import over_inputs
from ._explain_output import also_explaining, mean_refusal, summary
from ._mechanisms import Context, fit_gains, lead_with_explanation, mechanisms, named, named_classes
from ._shots import Model, model_shots
from ._verdict import as_json_fields, refusals, time_free, verdict
from . import _ambiguity

#: the significance level of the goodness-of-fit test (reference §4)
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
    return [n for n in names if n != "awgn" and (meas.t is not None or not REGISTRY[n].needs_times)
            and scope_error(REGISTRY[n], meas.arch.depth) is None]


#: a candidate's status (reference §6), in ranking order
STATUSES = ("passes", "refused", "fails")


def n_scalar_params(name: str, arch) -> int:
    """The scalar parameters effect ``name`` adds to a model: one per parameter, a per-layer one
    (``shape = "layers"``) once per layer of its scope."""
    cls = REGISTRY[name]
    n = 0
    for p in cls.params:
        if cls.shape.get(p) == "layers":
            n += sum(1 for l in range(1, arch.depth + 1) if cls.acts_on(cls, l, arch.depth))
        else:
            n += 1
    return n


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One fitted extension of the model, scored on held-out inputs.

    n_free : the parameters it adds, an offset family counted by its effective degrees of freedom
    nominal : the parameters it adds, every offset counted as one
    status : ``"passes"``, ``"refused"`` or ``"fails"`` (see the module); empty until checked
    refused_because : why a candidate that passes its test is not an explanation (status refused)
    lacks : refused (also) for something the identification finds that it has no term for (rules
        b'', b''', e, f, g): a second effect on top of it may be what is missing
    """

    effects: tuple
    model: Model
    comparison: Comparison
    score: float
    seconds: float
    n_free: float = 0.0
    nominal: int = 0
    status: str = ""
    refused_because: tuple = ()
    lacks: bool = False

    @property
    def name(self) -> str:
        return "+".join(self.effects)

    def mechanism(self) -> str:
        return "+".join(REGISTRY[e].mechanism for e in self.effects)

    def as_json(self) -> dict:
        # a second-stage entry is named by the effect it adds; "with" lists the ones before
        out = {"effect": self.effects[-1], "mechanism": self.mechanism(), "status": self.status,
               "discrepancy_after": self.comparison.discrepancy, "p_value_after": self.comparison.p_value,
               "params": self.model.params_json(), "se": self.comparison.se, "score": self.score,
               "n_free": self.n_free, "nominal_params": self.nominal}
        if len(self.effects) > 1:
            out["with"] = list(self.effects[:-1])
        if self.refused_because:
            out["refused_because"] = list(self.refused_because)
        from ._intervals import per_neuron_json  # reference §2b: per-neuron values and their standard errors
        out.update(per_neuron_json(self.model))
        if self.comparison.replicates:
            out["net_discrepancy_after"] = self.comparison.net_discrepancy
            out["refit_null_replicates"] = self.comparison.replicates
            out["fitted_offsets"] = sorted(self.model.offsets)
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


def model_key(model: Model) -> tuple[str, str]:
    """A model's identity by content: its name (its effects, joined by "+") and a digest of every
    value it was fitted to (physics parameters, offset scales, the weights it runs with)."""
    h = hashlib.sha1()

    def add(tag, v):
        h.update(tag.encode())
        rows = v if isinstance(v, (tuple, list)) else (v,)
        for row in rows:
            h.update(np.ascontiguousarray(np.asarray(row, np.float64)).tobytes())

    for k, v in sorted(model.physics.params().items()):
        add(k, v)
    for k, v in sorted(model.offsets.items()):
        add("offset:" + k, v)
    if model.params is not None:
        for l, (W, b) in enumerate(model.params):
            add(f"W{l}", W)
            add(f"b{l}", b)
    return "+".join(model.effects), h.hexdigest()


def name_key(key, name: str):
    """``key`` folded with a model's name (its own stream: the same name, the same numbers)."""
    return jax.random.fold_in(key, zlib.crc32(name.encode()) & 0x7FFFFFFF)


class _Memo:
    """A thread-safe memo of pure functions: ``get(key, make)`` returns ``make()``, made once per
    key (a second thread asking for a key being made waits for it). The key must determine the
    value: then what a caller gets never depends on what was asked before."""

    def __init__(self):
        self._done, self._making, self._lock = {}, {}, threading.Lock()

    def get(self, key, make):
        with self._lock:
            if key in self._done:
                return self._done[key]
            lock = self._making.setdefault(key, threading.Lock())
        with lock:
            with self._lock:
                if key in self._done:
                    return self._done[key]
            value = make()
            with self._lock:
                self._done[key] = value
        return value


@dataclasses.dataclass(frozen=True, eq=False, init=False)
class Session:
    """What every model scored on one measurement shares: the split of its inputs, the held-out
    half's :class:`Reference`, the fitting half's moments and the baseline. Built once by
    :func:`diagnose`, :func:`fit_effects` and :func:`compare_measurement` from the same named
    subkeys, so their numbers agree.

    Immutable and pure: its fields are set once; what it computes for a model (the refit null of
    a model with fitted offsets, the checks of its fitted values) is a function of the model's
    content (:func:`model_key`) and the session's subkeys -- the refit null's key is folded with
    the model's name -- kept in a memo keyed by that content, so the numbers do not depend on
    the order models are scored in or on the number of threads (``workers``).
    """

    meas: Measurement
    shots: int | None
    workers: int
    k_fit: object
    k_cmp: object
    k_step: object
    train: np.ndarray
    test: np.ndarray
    fit_meas: Measurement
    test_meas: Measurement
    ref: Reference
    problem: MomentProblem
    baseline: Model | None
    baseline_comparison: Comparison | None
    _memo: _Memo

    def __init__(self, key, meas: Measurement, shots: int | None = None, workers: int | None = None):
        put = functools.partial(object.__setattr__, self)
        put("meas", meas)
        put("shots", shots)
        # threads for the refit nulls' replicates and the candidates (the numbers do not depend on it)
        put("workers", default_workers(meas) if workers is None else max(1, int(workers)))
        k_split, k_fit, k_cmp, k_ref, k_step = jax.random.split(key, 5)
        for name, v in (("k_fit", k_fit), ("k_cmp", k_cmp), ("k_step", k_step)):
            put(name, v)
        train, test = split_inputs(k_split, meas.n)
        put("train", train)
        put("test", test)
        put("fit_meas", meas.subset(train))
        put("test_meas", meas.subset(test))
        put("ref", reference(k_ref, self.test_meas))
        put("problem", MomentProblem(self.k_fit, self.fit_meas, shots))
        put("_memo", _Memo())
        put("baseline", None)  # fit() reads it: offsets fitted from scratch start from it
        put("baseline", self.fit(()))
        put("baseline_comparison", None)
        put("baseline_comparison", self.score(self.baseline))

    def fit(self, effects, start: Model | None = None) -> Model:
        return fit_model(self.k_fit, self.fit_meas, effects, start=start, K=self.shots, problem=self.problem,
                         baseline=self.baseline)

    def prior(self, model: Model) -> list:
        """:func:`~gift_theory.lab._offset_prior.prior_check` of a fitted model on the fitting half
        (the mechanisms' fit gains and the checks both read it; [] without offsets)."""
        if not any(model.offsets):
            return []
        return self._memo.get(("prior",) + model_key(model), lambda: prior_check(model, self.fit_meas))

    def full_reference(self) -> Reference:
        """The noise floor of every input (the one-step checks' reference), made once."""
        return self._memo.get(("full_reference",), lambda: reference(named_subkey(self.k_step, "floor"), self.meas))

    def one_step(self, model: Model, own_level: bool = True) -> list:
        """The one-step check of every layer of ``model`` on every input (with taps)."""
        return self._memo.get(("one_step", own_level) + model_key(model), lambda: list(one_step_check(
            self.k_step, model, self.meas, ref=self.full_reference(), own_level=own_level)))

    def refit_null(self, model: Model) -> list:
        """The refit null of a model with fitted offsets (:func:`offset_replicates`), its key folded
        with the model's name."""
        name = "+".join(model.effects)
        return self._memo.get(("refit_null",) + model_key(model), lambda: offset_replicates(
            name_key(self.k_cmp, name), model, self.fit_meas, self.test_meas, self.ref, channel_values=channel_values,
            shots=self.shots, workers=self.workers))

    def score(self, model: Model, plain: Comparison | None = None, held_out: Measurement | None = None) -> Comparison:
        """The held-out comparison; a model with fitted offsets against its own refit null. With
        taps, a model whose plain test already rejects at :data:`REFIT_SKIP_P` skips the refit
        null: there the offsets are identified and their estimation error shifts the
        discrepancy by a few of its standard deviations (measured: 5.5 on docs/lab.md's
        weight_error example), far less than such a rejection needs (some 30). ``plain``: the
        model's plain comparison, if already made.

        ``held_out``: a variant of the held-out half with the same data (the verdict's time-free
        twin holds the acquisition times at their mean), scored against the same reference."""
        offsets = any(fitted_as_offsets(n) for n in model.offsets)
        test_meas = self.test_meas if held_out is None else held_out
        if plain is None:
            plain = compare(self.k_cmp, model, test_meas, shots=self.shots, ref=self.ref)
        if not offsets or (self.meas.has_taps and plain.p_value < REFIT_SKIP_P):
            return plain
        return compare(self.k_cmp, model, test_meas, shots=self.shots, ref=self.ref,
                       null_replicates=self.refit_null(model))

    def checks(self, cand: "Candidate") -> "Candidate":
        """``cand`` with its status: ``"fails"`` below 0.01, else ``"passes"`` or ``"refused"`` by
        the verdict's rule (:func:`~gift_theory.lab._verdict.refusals`: its fitted values against
        their prior, with taps every layer's one-step check, a time effect against its time-free
        twin, and whether it buys its keep)."""
        if cand.comparison.p_value < ALPHA:
            return dataclasses.replace(cand, status="fails", refused_because=())
        steps = self.one_step(cand.model, own_level=False) if self.meas.has_taps else None
        twin = None
        if self.meas.t is not None and any(REGISTRY[e].needs_times for e in cand.effects):
            twin = self.score(cand.model, held_out=time_free(self.test_meas))
        why = refusals(cand, self.baseline_comparison, steps, self.prior(cand.model), twin)
        return dataclasses.replace(cand, status="refused" if why else "passes", refused_because=tuple(why))

    def _prepare(self, start, fit_names, added):
        """Fit, score and check one candidate: pure."""
        t0 = time.time()
        model = self.fit(fit_names, start=start)
        n_free, nominal = 0.0, 0
        for name in added:
            if fitted_as_offsets(name):
                dof, nom = effective_dof(self.k_fit, self.fit_meas, model, kinds_of([name], self.meas.arch))
                n_free, nominal = n_free + dof, nominal + nom
            else:
                k = n_scalar_params(name, self.meas.arch)
                n_free, nominal = n_free + k, nominal + k
        cmp = self.score(model)
        return model, cmp, n_free, nominal, time.time() - t0

    def candidates(self, requests, progress=None) -> list:
        """Fit, score and check ``requests``: (effects, start model or None, the effects to fit
        on top of it, the effects whose parameters the candidate is charged for), ... Returned
        in the order of ``requests``, each with its status (:meth:`checks`).

        Each candidate is a pure function of its request, so the session's ``workers`` threads
        run them at once (JAX's programs and numpy's sorts run without the GIL): same numbers
        for any number of threads and any order of ``requests``.

        ``progress(i, n, label)``: called as each candidate is done (i counts them from 0)."""
        requests = list(requests)
        done = [0]
        lock = threading.Lock()

        def report(cand):
            if progress is not None:
                with lock:
                    progress(done[0], len(requests), f"{cand.name}: {cand.status}")
                    done[0] += 1
            return cand

        def one(r):
            effects, *rest = r
            model, cmp, n_free, nominal, seconds = self._prepare(*rest)
            cand = Candidate(tuple(effects), model, cmp, penalised_score(cmp, n_free, self.baseline_comparison),
                             seconds, float(n_free), int(nominal))
            return report(self.checks(cand))

        if self.workers > 1 and len(requests) > 1:
            with concurrent.futures.ThreadPoolExecutor(max_workers=self.workers) as pool:
                # each task in a copy of this context, so a PhaseClock still sees its compiles
                futs = [pool.submit(contextvars.copy_context().run, one, r) for r in requests]
                return [f.result() for f in futs]
        return [one(r) for r in requests]


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
    not_fitted: tuple = ()
    output_explanations: tuple = ()
    #: the verdict names the awgn model itself (it passes and the identification flags nothing):
    #: the JSON ranking then starts with it (reference §6: ranking[0] is what the verdict names)
    names_baseline: bool = False
    #: the models that explain the data, ranking[0] first (reference §8; empty when not explained)
    explained_by: tuple = ()
    #: the candidates the data cannot tell from ranking[0] (:mod:`._ambiguity`)
    ambiguous_with: tuple = ()
    #: the measurement that would tell the hypotheses left standing apart (:mod:`._design`), or None
    next_measurement: dict | None = None

    @property
    def missing_effect_detected(self) -> bool:
        return bool(self.baseline_comparison.p_value < ALPHA)

    def _baseline_entry(self) -> dict:
        """The awgn model as a ranking entry (``"baseline": true``: nothing added to it)."""
        c = self.baseline_comparison
        return {"effect": self.baseline.effects[-1], "mechanism": "+".join(REGISTRY[e].mechanism
                                                                           for e in self.baseline.effects),
                "status": "passes", "baseline": True, "discrepancy_after": c.discrepancy, "p_value_after": c.p_value,
                "params": self.baseline.params_json(), "se": c.se, "score": penalised_score(c, 0.0, c),
                "n_free": 0.0, "nominal_params": 0}

    def as_json(self) -> dict:
        """The reference §4 object of ``gift diagnose --json`` (plus a few extra keys)."""
        c = self.baseline_comparison
        return {"baseline": {"effects": self.baseline.effects, "params": self.baseline.params_json(),
                             "discrepancy": c.discrepancy, "noise_floor": c.noise_floor, "p_value": c.p_value,
                             "se": c.se, "floor_se": c.floor_se, "channel_z": c.as_dict()["channel_z"]},
                "missing_effect_detected": self.missing_effect_detected,
                **as_json_fields(self.explained, self.reasons, self.verdict, self.failing_layers, self.mechanisms),
                "ranking": _ambiguity.mark(([self._baseline_entry()] if self.names_baseline else [])
                                           + [cand.as_json() for cand in self.ranking],
                                           self.ranking[0] if self.ranking else None, self.ambiguous_with),
                "explained_by": list(self.explained_by),
                "next_measurement": _public_design(self.next_measurement),
                "not_fitted": [dict(r) for r in self.not_fitted],
                **({"output_explanations": list(self.output_explanations)} if self.output_explanations else {}),
                "evidence": list(self.evidence),
                "where": list(self.one_step),
                "signatures": self.signatures,
                "worst_cells": [] if self.where is None else self.where["worst"][:10],
                "held_out_inputs": int(len(self.held_out)),
                **({"refit_null_calibrated": self.has_taps} if any(c.comparison.replicates for c in self.ranking)
                   else {}),
                "seconds": self.seconds}


def _public_design(nxt):
    from ._design import public

    return public(nxt)


def _status(c: Candidate) -> str:
    return c.status or ("fails" if c.comparison.p_value < ALPHA else "passes")


def rank_key(c: Candidate):
    """The order of the ranking (reference §6): those that pass, then the refused ones, then those
    the data reject; among those that pass by penalised score (the parsimony of reference §4),
    among the others by held-out discrepancy; ties by name (the order never depends on the
    order the candidates were scored in)."""
    status = _status(c)
    within = c.score if status == "passes" else c.comparison.discrepancy
    return (STATUSES.index(status), within, c.name)


def ranked(cands) -> list:
    """``cands`` in the ranking's order (:func:`rank_key`)."""
    return sorted(cands, key=rank_key)


def search_key(c: Candidate):
    """The greedy second step's order: the candidates that pass their test first, each group by
    penalised score (a failing per-device offset family with hundreds of effective parameters
    must not become the first effect a pair is built on), ties by name."""
    return (c.comparison.p_value < ALPHA, c.score, c.name)


def _merge_second_stage(first: Candidate, stage2: list, singles: list) -> list:
    """Every candidate after the greedy second step, in the ranking's order: the pairs, the first
    effect, and the singles not tried on top of it (a runner-up tried on top of the first is
    listed as the pair only)."""
    named = {c.effects[-1] for c in stage2}
    return ranked(list(stage2) + [first] + [c for c in singles if c.effects[0] not in named])


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
            if scope_error(REGISTRY[e], meas.arch.depth):
                raise GiftInputError(f"--candidates {e}: {scope_error(REGISTRY[e], meas.arch.depth)}")
    return list(names)


#: runners-up fitted on top of a failing first effect (the greedy second step)
SECOND = 4


def flagged_classes(ident) -> dict:
    """``{class: smallest Holm-adjusted p}`` of the identification's tests that reject at 0.01: the
    mechanism classes the closed-form identification sees in the data."""
    out: dict = {}
    for row in ([] if ident is None else ident.rows()):
        if row.get("p_adj", 1.0) < ALPHA:
            out[row["class"]] = min(out.get(row["class"], 1.0), float(row["p_adj"]))
    return out


def _classes(name: str) -> set:
    return {REGISTRY[e].mechanism for e in name.split("+")}


def _refuse(c, why, lacks: bool = False):
    return dataclasses.replace(c, status="refused", refused_because=tuple(c.refused_because) + (why,),
                               lacks=c.lacks or lacks)


def _where(rows) -> str:
    best = min(rows, key=lambda r: r["p_adj"])
    return f"at layer(s) {', '.join(map(str, sorted({int(r['layer']) for r in rows})))}, p = {best['p_adj']:.2g}"


def _law_check(session: "Session", ident):
    """Rule f of :mod:`._verdict`, or None when it has nothing to read: when the identification
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


#: rule g refuses a candidate whose correlations differ at this level (Bonferroni over the
#: layers) even when they moved from the baseline's towards the measured ones
STRICT = 1e-4


def _corr_z(shots, r: int):
    """(n, K // r, pairs): per input and sample of r consecutive shots of ``shots`` (n, K, d),
    Fisher's z (atanh) of the correlation of each pair of neurons (on at most
    :data:`~gift_theory.lab._identify.WIDE` of them) -- a measurement's r shots (one sample) or a
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


def _cov_check(session: "Session", ident):
    """Rule g of :mod:`._verdict`, or None when it has nothing to read: when the identification
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


def _against_baseline(session: "Session", stats_of, compare, say):
    """The skeleton of rules f and g: ``check(candidate)``, the sentence refusing it or None.
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


def _checks(*checks):
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


def _identification_refusals(cands: list, ident, base_cmp=None, law=None) -> list:
    """Rules b'', b''', e, f and g of :mod:`._verdict`: a candidate that passes its held-out test is refused
    when the identification finds (:func:`~gift_theory.lab._mechanisms.named`: Holm-adjusted
    0.01) something that test cannot see and the candidate has no term for.

    * b'': a trend in acquisition time (a time_drift test). The held-out test compares
      per-input means, which average an interleaved acquisition's trend away (a bias drift
      passed as layer_gain without taps, a gain drift as activation_gain). Refused: a candidate
      with no effect that acts through the times (other than a memory).
    * b'' for memory (issue 48): the shots carry the shot acquired before them (the memory
      class's lag test). The held-out test compares each input's shots, whatever order they
      were taken in (a detector's memory passed as bias offsets). Refused: a candidate with no
      effect of class memory; and the converse, a candidate with a memory where the lag test
      names none (a memory's shift and excess variance of each neuron are what other physics
      gives too).
    * b''': any class, when the baseline itself passes its held-out test (``base_cmp``): that
      test has no power against what the identification finds (Student-t noise in one layer of a
      tapped chip passed as awgn at p = 0.40 while the kurtosis test rejected awgn with z = 10.7). Refused: a
      candidate with no effect of a flagged class.
    * e (without taps): the candidate mechanisms put into the model
      (:mod:`._explain_output`) say its class does not reproduce the output's mean while another
      class does (:func:`~gift_theory.lab._explain_output.mean_refusal`): the detectors' gain and
      offset passed as layer_gain (p = 0.22) while no gain put into the model fitted every
      input's mean and each output neuron's own gain and offset did.
    * f and g: ``law`` (:func:`_law_check` and :func:`_cov_check`, composed), when the
      identification names noise_law by its kurtosis, or a covariance across a layer's neurons:
      a candidate whose own shots' tails, or correlations, differ from the measured ones and
      have not moved towards them from the baseline's.

    Each refusal here marks the candidate ``lacks``: when none passes, the greedy second step
    builds on it."""
    if ident is None:
        return cands
    rows = [r for r in ident.rows() if named(r, ident.taps)]
    cands_out = getattr(ident, "output_candidates", ()) if not ident.taps else ()
    trend = [r for r in rows if r["class"] == "time_drift"]
    memory = [r for r in rows if r["class"] == "memory"]  # issue 48 (lab/_memory.py)
    t_ok = any(r["class"] == "memory" and r["test"] == "lag" for r in ident.rows())  # the lag test ran
    silent = base_cmp is not None and base_cmp.p_value >= ALPHA
    flagged = sorted({r["class"] for r in rows})
    out = []
    for c in cands:
        name = " + ".join(c.effects)
        if c.status == "passes" and trend and not any(REGISTRY[e].needs_times and REGISTRY[e].mechanism != "memory"
                                                       for e in c.effects):
            c = _refuse(c, f"the identification finds a trend in acquisition time (time_drift {_where(trend)}) that "
                           f"awgn + {name} has no term for: its held-out test compares per-input means, which "
                           f"average the trend away", lacks=True)
        if (c.status == "passes" and not memory and t_ok and any(REGISTRY[e].mechanism == "memory" for e in c.effects)):
            c = _refuse(c, f"awgn + {name} has a memory the identification does not find (its lag test names no "
                           f"layer at Holm-adjusted 0.01): through each input's shots a memory is a shift and an excess "
                           f"variance of each neuron, which other physics gives too")
        if c.status == "passes" and memory and not any(REGISTRY[e].mechanism == "memory" for e in c.effects):
            c = _refuse(c, f"the identification finds that the shots carry the shot acquired before them (memory "
                           f"{_where(memory)}), which awgn + {name} has no term for: its held-out test compares each "
                           f"input's shots, not the order they were taken in", lacks=True)
        why = mean_refusal(_classes("+".join(c.effects)), cands_out) if c.status == "passes" and cands_out else None
        if why:
            c = _refuse(c, f"awgn + {name}: {why}", lacks=True)
        if c.status == "passes" and silent and flagged and not _classes("+".join(c.effects)) & set(flagged):
            found = "; ".join(f"{k} {_where([r for r in rows if r['class'] == k])}" for k in flagged)
            c = _refuse(c, f"the identification finds {found}, which awgn + {name} has no term for; the held-out "
                           f"test does not see it (the awgn model passes that test too, p = {base_cmp.p_value:.3g})",
                        lacks=True)
        why = law(c) if c.status == "passes" and law is not None else None
        if why:
            c = _refuse(c, why, lacks=True)
        out.append(c)
    return out


def _single(name: str) -> tuple:
    effects = tuple(name.split("+"))
    return effects, None, effects, effects


def _rank(session: Session, names, second, verbose: bool, ident=None, progress=None) -> tuple[list, list]:
    """The candidates fitted, scored, checked and ranked; a second stage on top of the best one
    when every one still fails (see :func:`diagnose`). Returns ``(ranking, not_fitted)``.

    First the candidates of a class the identification flags (:func:`flagged_classes`) are
    fitted; when one of them passes every check, the others are not fitted (the identification
    clears their classes, and an explanation has been found) and are listed in ``not_fitted``
    with that reason. Otherwise every candidate is fitted."""
    def fitted(specs):
        return _identification_refusals(session.candidates(specs, progress), ident, session.baseline_comparison,
                                        law)

    law = _checks(_law_check(session, ident), _cov_check(session, ident))

    flagged = flagged_classes(ident)
    # issue 48: the built-in memory is fitted only where the lag test names memory (through each
    # input's shots a memory is a shift and an excess variance per neuron, which the held-out test
    # cannot tell from other physics; lab/_memory.py)
    quiet = ident is not None and "memory" not in flagged and "memory" in names and len(names) > 1
    names = [n for n in names if not (quiet and n == "memory")]
    first = [n for n in names if _classes(n) & set(flagged)]
    rest = [n for n in names if n not in first]
    todo = first if first and rest else list(names)
    ranking = fitted([_single(n) for n in todo])
    not_fitted = []
    if todo is first:
        if any(c.status == "passes" for c in ranking):
            not_fitted = [{"effect": n, "mechanism": "+".join(sorted(_classes(n))),
                           "reason": "the identification clears its class (no test of it rejects at 0.01) and "
                                     "awgn + " + " + ".join(min((c for c in ranking if c.status == "passes"),
                                                               key=rank_key).effects)
                                     + " passes every check"} for n in rest]
        else:
            ranking += fitted([_single(n) for n in rest])
            todo = first + rest
    if quiet:
        not_fitted.append({"effect": "memory", "mechanism": "memory",
                           "reason": "the identification's lag test names no memory at Holm-adjusted 0.01"})
    for name, cand in zip(todo, ranking):
        _log(f"  + {name:<15s} {cand.model.describe():<60s} discrepancy {cand.comparison.discrepancy:.3g} "
             f"p = {cand.comparison.p_value:.3g} [{cand.status}] ({cand.seconds:.1f} s)", verbose)
    if not_fitted:
        _log(f"  not fitted (the identification clears their classes): {', '.join(r['effect'] for r in not_fitted)}",
             verbose)
    ranking.sort(key=search_key)
    if (second != 0 and len(ranking) > 1 and not any(_status(c) == "passes" for c in ranking)
            and (ranking[0].comparison.p_value < ALPHA or ranking[0].lacks)):
        # none passes, and the best fails its test or is refused for something the identification
        # finds that it has no term for (multiplicative noise, refused by rule g on
        # multiplicative + common-mode noise): the runners-up, each on top of it
        first = ranking[0]
        rest = [c.effects[0] for c in ranking[1:] if _compatible(first, c.effects[0])][:second]
        # on top of the first's fitted model; but a first refused for what it lacks is refitted
        # with each runner-up jointly: its fit gave the missing effect's share to its own
        # parameter (per-neuron multiplicative noise took the shared gain's variance, and
        # common_mode fitted on top of it went to c = 1e-6)
        joint = first.status == "refused" and first.lacks
        stage2 = fitted([(first.effects + (name,), None if joint else first.model,
                          first.effects + (name,) if joint else (name,), first.effects + (name,)) for name in rest])
        for cand in stage2:
            _log(f"  + {'+'.join(cand.effects):<30s} {cand.model.describe():<60s} discrepancy "
                 f"{cand.comparison.discrepancy:.3g} p = {cand.comparison.p_value:.3g}", verbose)
        return _merge_second_stage(first, stage2, ranking[1:]), not_fitted
    return ranked(ranking), not_fitted


def _alternatives(session: Session, ranking: list, not_fitted: list, ident, verbose: bool, progress=None):
    """Issue 48 (reference §8): without taps, when ranking[0] passes and the output's candidate
    mechanisms (:mod:`._explain_output`) say the output's mean is reproduced as well by classes
    of another group, the candidates of those classes left unfitted are fitted too, so the
    verdict can say when the data cannot choose between them (:mod:`._ambiguity`). Among models
    the data cannot tell apart, the one whose class the identification flags keeps the lead; one
    better by more than the ambiguity's margin leads. Returns ``(ranking, not_fitted)``."""
    from ._ambiguity import APART
    from ._explain_output import MAP_CLASSES, _group

    if ident is None or ident.taps or not ranking or ranking[0].status != "passes" or not not_fitted:
        return ranking, not_fitted
    top = ranking[0]
    mine = {_group(c) for c in _classes("+".join(top.effects))}
    also = {c.mechanism for c in getattr(ident, "output_candidates", ()) if c.explains
            and c.mechanism in MAP_CLASSES and _group(c.mechanism) not in mine}
    extra = [r["effect"] for r in not_fitted if _classes(r["effect"]) & also]
    if not extra:
        return ranking, not_fitted
    _log(f"  also fitted (the output's mean is reproduced as well by {', '.join(sorted(also))}): "
         f"{', '.join(extra)}", verbose)
    new = _identification_refusals(session.candidates([_single(n) for n in extra], progress), ident,
                                   session.baseline_comparison)
    out = ranked(list(ranking) + new)
    unit = session.baseline_comparison.se if session.baseline_comparison.se > 0 else 1.0
    if out[0] is not top and out[0].status == "passes" and top.score - out[0].score < APART * unit:
        out = [top] + [c for c in out if c is not top]
    return out, [r for r in not_fitted if r["effect"] not in extra]


def _localise(session: Session, base: Model, meas: Measurement, shots):
    """Where the baseline fails, each layer on its own: the one-step checks (with taps), the
    failing layers, the layer evidence, the signatures and where-it-fails (pure: keyed by
    the session's step key)."""
    taps = meas.has_taps
    steps = tuple(session.one_step(base)) if taps else ()
    failing = failing_layers(steps) if taps else None
    res = residuals(session.k_step, base, meas, shots)
    local = one_step_residuals(session.k_step, base, meas, {r["layer"]: r["s"] for r in steps}) if taps else res
    evidence = layer_evidence(local)
    sigs, where = signatures(session.k_step, base, meas, res=res), where_it_fails(session.k_step, base, meas, res=res)
    return steps, failing, evidence, sigs, where


def default_workers(meas: Measurement | None = None) -> int:
    """Threads for the candidates: the cores this process may use, at most 4 (``$GIFT_LAB_THREADS``),
    and -- given ``meas`` -- no more than :func:`~._budget.candidate_threads` allows for its size
    (each thread holds a candidate's model shots and statistics; the numbers do not depend on it)."""
    env = os.environ.get("GIFT_LAB_THREADS", "").strip()
    if env.isdigit() and int(env) >= 1:
        return int(env)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return max(1, min(4, cores, candidate_threads(meas) if meas is not None else 4))


def diagnose(key, meas: Measurement, *, candidates=None, shots: int | None = None, second: int | None = SECOND,
             verbose: bool = False, workers: int | None = None, progress=None, design: bool = False) -> Diagnosis:
    """Fit the baseline and every candidate effect; rank them on held-out inputs.

    Parameters
    ----------
    key : PRNG key (split into ``split``, ``fit``, ``compare``, ``floor``, ``step`` subkeys)
    meas : Measurement
    candidates : effect names to try (default :func:`default_candidates`: every registered effect but
        awgn; those that need acquisition times only when the file has them); those of a class
        the identification flags are fitted first, the others only when none of those passes
        (see the module)
    shots : model shots per input (default 4 r)
    second : when the best single effect still fails (p < 0.01), the best ``second``
        runners-up (default 4; None: all) are each fitted on top of it (a greedy forward step,
        for two missing effects) and ranked with the rest
    workers : threads fitting the candidates at once (default :func:`default_workers`); the
        numbers do not depend on it
    progress : ``progress(i, n, label)``, called as each candidate of a batch is done (the
        candidates of the flagged classes, the others if none of those passes, the second
        stage: each batch counts from 0 to its own n)
    design : whether to design the next measurement (:mod:`._design`) when the data do not choose
        between models, or nothing explains them (``gift diagnose`` does; it simulates a few
        hundred campaigns, so it is asked for here); without it ``next_measurement`` is None

    Returns
    -------
    Diagnosis
    """
    t0 = time.time()
    names = default_candidates(meas) if candidates is None else _check_candidates(candidates, meas)
    threads = default_workers(meas) if workers is None else max(1, int(workers))
    # the layer-wise identification (closed form, numpy: the mechanisms' backbone, and which
    # candidates to fit first) needs only the data: with threads to spare it runs beside the
    # baseline's fit, and localising -- which needs only the baseline -- beside the candidates
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as side:
        ident_f = side.submit(identify, meas) if threads > 1 else None
        session = Session(key, meas, shots, workers)
        base, base_cmp = session.baseline, session.baseline_comparison
        _log(f"baseline {base.describe()}: discrepancy {base_cmp.discrepancy:.3g} +- {base_cmp.se:.2g} "
             f"(floor {session.ref.noise_floor:.3g}), p = {base_cmp.p_value:.3g}", verbose)
        # the identification first (the candidates wait for it): localising starts when it is done
        ident = ident_f.result() if ident_f is not None else identify(meas)
        local = (side.submit(contextvars.copy_context().run, _localise, session, base, meas, shots)
                 if threads > 1 else None)
        ranking, not_fitted = _rank(session, names, second, verbose, ident, progress)
        ranking, not_fitted = _alternatives(session, ranking, not_fitted, ident, verbose, progress)  # issue 48
        steps, failing, evidence, sigs, where = (local.result() if local is not None
                                                 else _localise(session, base, meas, shots))
    taps = meas.has_taps
    # name mechanisms, then the verdict
    ctx = Context({row["layer"]: row for row in evidence}, meas.arch.depth, taps, failing,
                  fit_gains(ranking, base_cmp, session.prior), {r["layer"]: (r["s"], r["level_z"]) for r in steps},
                  ident=ident)
    mechs = mechanisms(ctx)
    flagged = named_classes(ident)
    explained, reasons, line = verdict(session, ranking, meas, mechs, failing, flagged)
    if explained and (base_cmp.p_value < ALPHA or flagged):  # a fitted effect explains: its class leads
        mechs = lead_with_explanation(mechs, ranking[0], base_cmp)
        also = None if taps else also_explaining(_classes("+".join(ranking[0].effects)), ident.output_candidates)
        if also:  # said, not hidden: the explanation is one of several the output allows
            reasons = list(reasons) + [also]
            line += "; " + also
    names_baseline = bool(explained and base_cmp.p_value >= ALPHA and not flagged)
    # ---- issue 48 hooks: the models the data cannot tell apart (lab/_ambiguity.py), and the
    # measurement that would (lab/_design.py)
    others = _ambiguity.peers(ranking, base_cmp) if explained and not names_baseline else []
    if others:
        amb = _ambiguity.sentence(ranking[0], others, base_cmp)
        reasons = list(reasons) + [amb]
        line += "; " + amb
    by = (["awgn"] if names_baseline else _ambiguity.explained_by(ranking[0], others)) if explained else []
    nxt = None
    if design and not names_baseline and (others or not explained):
        from ._design import next_measurement
        nxt = next_measurement(named_subkey(key, "design"), meas, ranking, mechs, others if explained else None,
                               base_cmp)
    _log(line, verbose)
    return Diagnosis(base, base_cmp, tuple(ranking), steps, session.test, time.time() - t0, taps, sigs, where,
                     explained, tuple(reasons), line, None if failing is None else tuple(failing), tuple(mechs),
                     tuple(evidence), tuple(not_fitted), tuple(summary(ident.output_candidates)),
                     names_baseline=names_baseline, explained_by=tuple(by), ambiguous_with=tuple(others),
                     next_measurement=nxt)


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of :func:`fit_effects`: the model before and after adding effects."""

    before: Model
    after: Model
    comparison_before: Comparison
    comparison_after: Comparison
    ladder: tuple  # ((label, Comparison), ...) one rung per added effect
    has_taps: bool = False
    held_out: np.ndarray | None = None  # the inputs scored (indices into the measurement)

    def as_json(self) -> dict:
        """The reference §4 object of ``gift fit --json`` (plus a few extra keys)."""
        a, b = self.comparison_after, self.comparison_before
        return {"effects": self.after.effects, "params": self.after.params_json(),
                "discrepancy_before": b.discrepancy, "discrepancy_after": a.discrepancy,
                "noise_floor": a.noise_floor, "p_value_after": a.p_value,
                "p_value_before": b.p_value, "se_before": b.se, "se_after": a.se, "floor_se": a.floor_se,
                "ladder": [{"model": lab, "discrepancy": c.discrepancy, "se": c.se, "p_value": c.p_value,
                            **({"net_discrepancy": c.net_discrepancy} if c.replicates else {})}
                           for lab, c in self.ladder],
                **({"net_discrepancy_after": a.net_discrepancy, "refit_null_replicates": a.replicates,
                    "refit_null_calibrated": self.has_taps, "fitted_offsets": sorted(self.after.offsets)}
                   if a.replicates else {})}


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
        if scope_error(REGISTRY[e], meas.arch.depth):
            raise GiftInputError(f"--add {e}: {scope_error(REGISTRY[e], meas.arch.depth)}")
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
    return FitResult(base, model, base_cmp, cmp, tuple(ladder), meas.has_taps, session.test)


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
