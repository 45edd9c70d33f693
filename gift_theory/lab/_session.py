"""The session of one measurement: the split of its inputs, the held-out reference, the fitting
half's moments and the baseline, made once by :meth:`Session.create`; what it computes for a
model is a pure function of the model's content and the session's subkeys, kept in an explicit
cache (:class:`Memo`)."""

from __future__ import annotations

import dataclasses
import hashlib
import threading
import time
import zlib

import jax
import numpy as np

from .. import _random
from .._errors import GiftInputError
from .._measurement import Measurement
from .._model import named_subkey
from .._process import release_freed_memory
from ..effects import REGISTRY
from ._budget import default_workers, map_in_threads, replicate_threads
from ._channels import Reference, channel_values, reference
from ._compare import Comparison, compare, one_step_check
from ._fit import fit_model
from ._fit_moments import MomentProblem
from ._level import ALPHA
from ._offset_kinds import fitted_as_offsets, kinds_of
from ._offset_null import effective_dof, offset_replicates
from ._offset_prior import prior_check
from ._results import Candidate, n_scalar_params, penalised_score
from ._shots import Model
from ._verdict import refusal_rules, time_free


#: with taps, an offset model whose plain held-out test gives p below this is not run against
#: its refit null (:meth:`Session.score`)
REFIT_SKIP_P = 1e-30


def split_inputs(key, n: int, frac: float = 0.5):
    """Random disjoint (fit, held-out) index arrays over ``n`` inputs."""
    if n < 4:
        raise GiftInputError(f"measurement has {n} inputs; fitting and held-out scoring need at least 4")
    perm = _random.permutation(key, n)  # jax.random.permutation's
    k = n - int(round(n * (1 - frac)))  # held-out half n // 2 (equal halves share compiled shapes)
    k = min(max(k, 2), n - 2)
    return np.sort(perm[:k]), np.sort(perm[k:])


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


class Memo:
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


@dataclasses.dataclass(frozen=True, eq=False)
class Session:
    """What every model scored on one measurement shares: the split of its inputs, the held-out
    half's :class:`Reference`, the fitting half's moments and the baseline. Made by
    :meth:`create` (as :func:`diagnose`, :func:`fit_effects` and :func:`compare_measurement` do)
    from the same named subkeys, so their numbers agree.

    Immutable and pure: every field is set once, by :meth:`create`; what it computes for a model
    (the refit null of a model with fitted offsets, the checks of its fitted values) is a
    function of the model's content (:func:`model_key`) and the session's subkeys -- the refit
    null's key is folded with the model's name -- kept in its ``cache`` (a :class:`Memo`, the one
    mutable object it holds, keyed by that content), so the numbers do not depend on the order
    models are scored in or on the number of threads (``workers``).
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
    cache: Memo = dataclasses.field(repr=False)

    @classmethod
    def create(cls, key, meas: Measurement, shots: int | None = None, workers: int | None = None) -> "Session":
        """The session of ``meas`` under ``key``: the split, the held-out reference, the fitting
        half's moments, then the baseline (awgn, s fitted) and its held-out comparison.

        Parameters
        ----------
        key : PRNG key (split into ``split``, ``fit``, ``compare``, ``reference``, ``step`` subkeys)
        meas : Measurement
        shots : model shots per input (default 4 r)
        workers : threads for the refit nulls' replicates and the candidates (default
            :func:`default_workers`; the numbers do not depend on it)
        """
        workers = default_workers(meas) if workers is None else max(1, int(workers))
        k_split, k_fit, k_cmp, k_ref, k_step = jax.random.split(key, 5)
        train, test = split_inputs(k_split, meas.n)
        fit_meas, test_meas = meas.subset(train), meas.subset(test)
        bare = cls(meas, shots, workers, k_fit, k_cmp, k_step, train, test, fit_meas, test_meas,
                   reference(k_ref, test_meas), MomentProblem(k_fit, fit_meas, shots), None, None, Memo())
        baseline = bare.fit(())  # offsets fitted from scratch start from the baseline: none yet
        return dataclasses.replace(bare, baseline=baseline, baseline_comparison=bare.score(baseline))

    def fit(self, effects, start: Model | None = None) -> Model:
        return fit_model(self.k_fit, self.fit_meas, effects, start=start, K=self.shots, problem=self.problem,
                         baseline=self.baseline)

    def prior(self, model: Model) -> list:
        """:func:`~gift_theory.lab._offset_prior.prior_check` of a fitted model on the fitting half
        (the mechanisms' fit gains and the checks both read it; [] without offsets)."""
        if not any(model.offsets):
            return []
        return self.cache.get(("prior",) + model_key(model), lambda: prior_check(model, self.fit_meas))

    def full_reference(self) -> Reference:
        """The noise floor of every input (the one-step checks' reference), made once."""
        return self.cache.get(("full_reference",), lambda: reference(named_subkey(self.k_step, "floor"), self.meas))

    def one_step(self, model: Model, own_level: bool = True) -> list:
        """The one-step check of every layer of ``model`` on every input (with taps)."""
        return self.cache.get(("one_step", own_level) + model_key(model), lambda: list(one_step_check(
            self.k_step, model, self.meas, ref=self.full_reference(), own_level=own_level)))

    def refit_null(self, model: Model) -> list:
        """The refit null of a model with fitted offsets (:func:`offset_replicates`), its key folded
        with the model's name."""
        name = "+".join(model.effects)
        return self.cache.get(("refit_null",) + model_key(model), lambda: offset_replicates(
            name_key(self.k_cmp, name), model, self.fit_meas, self.test_meas, self.ref, channel_values=channel_values,
            shots=self.shots, workers=replicate_threads(self.meas, self.workers)))

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
        the verdict's rule (:func:`~gift_theory.lab._verdict.refusal_rules`: its fitted values against
        their prior, with taps every layer's one-step check, a time effect against its time-free
        twin, and whether it buys its keep)."""
        if cand.comparison.p_value < ALPHA:
            return dataclasses.replace(cand, status="fails", refused_because=(), refused_for=())
        steps = self.one_step(cand.model, own_level=False) if self.meas.has_taps else None
        twin = None
        if self.meas.t is not None and any(REGISTRY[e].needs_times for e in cand.effects):
            twin = self.score(cand.model, held_out=time_free(self.test_meas))
        why = refusal_rules(cand, self.baseline_comparison, steps, self.prior(cand.model), twin)
        return dataclasses.replace(cand, status="refused" if why else "passes",
                                   refused_because=tuple(w for _, w in why), refused_for=tuple(k for k, _ in why))

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
            release_freed_memory()  # the candidate's temporaries back to the system, not kept for the next
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

        return map_in_threads(one, requests, self.workers)
