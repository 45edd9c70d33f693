"""The lab's pipeline: which effect is missing, or -- when none it knows explains the data -- where to look.

One :func:`diagnose` reads top-down as the stages of the lab::

    split the inputs        (fit half, held-out half; the session)            ._session
    model shots             (the core's sampler and forward pass)             ._shots
    fit a model             (moments, offsets, values read off the data)      ._fit
    score its discrepancy   (channels, the Q-test, the noise floor)           ._compare
    check each that passes  (identified? its own effect? every layer?)        ._verdict
    rank                    (passes, refused, fails; a second step)           ._ranking
    localise                (one-step check per layer, residual profiles)     ._localise
    name mechanisms         (rules from the localised evidence)               ._mechanisms
    verdict                 (explained? what remains, where to look)          ._verdict

The baseline (awgn, s fitted) and every candidate ``awgn + effect`` (every registered effect
by default: the built-in ones and any plugin) are fitted on the fitting half and scored on
the held-out half. ``missing_effect_detected`` is the baseline's goodness-of-fit test,
``p_value < 0.01``. A model with fitted offsets is tested against a refit null
(:mod:`._offset_fit`, :mod:`._offset_null`).

**Status and order** (reference §6). Every candidate has a ``status``:
``"passes"`` (p >= 0.01 and every check of the verdict's rule holds: its values identified and
its own effect's, with taps every layer right, and it buys its keep -- :mod:`._verdict`),
``"refused"`` (p >= 0.01 but a check refuses it) or ``"fails"`` (p < 0.01). The ranking lists
those that pass, then the refused ones, then those the data reject (:func:`._ranking.ranked`); among those
that pass by the penalised held-out discrepancy ``discrepancy_after + 2 sd * (parameters the
effect adds)`` (sd the baseline's standard deviation of the discrepancy, a per-device offset
family counted by its effective degrees of freedom: reference §4's parsimony, so a
one-parameter effect that explains the data beats a many-parameter one that also does), among
the refused and the rejected by the held-out discrepancy itself. So ranking[0] is the model the
verdict line names, and an effect the data reject at 0.01 is never first while another entry
passes or is refused.

**Which candidates are fitted.** The closed-form identification (:mod:`.identification`, every
class a test with a Holm-adjusted p-value) runs first. The candidates of the classes it flags
(a test rejecting at 0.01) are fitted first; when one of them passes every check, the others --
whose classes no test flags -- are not fitted and are listed under ``not_fitted`` with that
reason (an explanation has been found, and the data show nothing of their physics). When none
passes, every candidate is fitted, as if the identification had said nothing.

**Pure.** A :class:`~._session.Session` is immutable: what it computes for a model -- its refit null, the
checks of its fitted values -- depends on the model (its name and fitted values) and the
session's named subkeys only, never on what was scored before it or on how many threads
score at once; the memo that spares recomputing them is keyed by that content.
"""

from __future__ import annotations

import concurrent.futures
import contextvars
import time

import jax

from .._errors import GiftInputError
from .._measurement import Measurement
from .._model import named_subkey
from .._process import release_freed_memory
from ..effects import BUILTIN, REGISTRY
from ..effects._physics import scope_error
from . import _ambiguity
from ._budget import default_workers, localise_beside
from ._channels import reference
from ._compare import compare, failing_layers, one_step_check
from ._explain_output import also_explaining, summary
from ._level import ALPHA
from ._localise import layer_evidence, one_step_residuals, residuals, signatures, where_it_fails
from ._mechanisms import Context, fit_gains, lead_with_explanation, mechanisms, named_classes
from ._ranking import SECOND, _log, rank_candidates, with_alternatives
from ._results import Diagnosis, FitResult
from ._session import Session
from ._shots import Model
from ._verdict import mechanism_classes, verdict
from .identification import identify


def default_candidates(meas: Measurement) -> list[str]:
    """Every registered effect a diagnosis of ``meas`` tries: all but awgn, and those silent
    without acquisition times only when the file has them."""
    names = list(BUILTIN) + [n for n in REGISTRY if n not in BUILTIN]  # catalogue order, then plugins
    return [n for n in names if n != "awgn" and (meas.t is not None or not REGISTRY[n].needs_times)
            and scope_error(REGISTRY[n], meas.arch.depth) is None]


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


def _localise(session: Session, base: Model, meas: Measurement, shots):
    """Where the baseline fails, each layer on its own: the one-step checks (with taps), the
    failing layers, the layer evidence, the signatures and where-it-fails (pure: keyed by
    the session's step key)."""
    taps = meas.has_taps
    steps = tuple(session.one_step(base)) if taps else ()
    failing = failing_layers(steps) if taps else None
    if taps:  # the one-step residuals first, given back before the baseline's own are made
        local = one_step_residuals(session.k_step, base, meas, {r["layer"]: r["s"] for r in steps})
        evidence = layer_evidence(local)
        del local  # (its model shots: as large as the measurement's taps, four times over)
        release_freed_memory()
    res = residuals(session.k_step, base, meas, shots)
    if not taps:
        evidence = layer_evidence(res)
    sigs = signatures(session.k_step, base, meas, res=res)
    release_freed_memory()
    where = where_it_fails(session.k_step, base, meas, res=res)
    release_freed_memory()
    return steps, failing, evidence, sigs, where


def diagnose(key, meas: Measurement, *, candidates=None, shots: int | None = None, second: int | None = SECOND,
             verbose: bool = False, workers: int | None = None, progress=None, design: bool = False,
             ranked=None) -> Diagnosis:
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
    ranked : ``ranked(baseline, baseline_comparison, ranking, held_out)``, called once the
        ranking is final, while the localisation may still run (``gift diagnose`` draws the
        figures that need no more then: :class:`~gift_theory.lab.DiagnosisFigures`); it must not
        change what it is given. No number of the diagnosis depends on it

    Returns
    -------
    Diagnosis
    """
    t0 = time.time()
    names = default_candidates(meas) if candidates is None else _check_candidates(candidates, meas)
    threads = default_workers(meas) if workers is None else max(1, int(workers))
    # the layer-wise identification (closed form, numpy: the mechanisms' backbone, and which
    # candidates to fit first) needs only the data: with threads to spare it runs beside the
    # baseline's fit, and localising -- which needs only the baseline -- starts as soon as the
    # baseline is fitted, beside the rest of the identification and the candidates, when the
    # memory budget holds a thread for it (after the candidates otherwise)
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as side:
        ident_f = side.submit(identify, meas) if threads > 1 else None
        session = Session.create(key, meas, shots, workers)
        base, base_cmp = session.baseline, session.baseline_comparison
        _log(f"baseline {base.describe()}: discrepancy {base_cmp.discrepancy:.3g} +- {base_cmp.se:.2g} "
             f"(floor {session.ref.noise_floor:.3g}), p = {base_cmp.p_value:.3g}", verbose)
        local = (side.submit(contextvars.copy_context().run, _localise, session, base, meas, shots)
                 if threads > 1 and localise_beside(meas, threads) else None)
        # the candidates wait for the identification (it says which to fit first)
        ident = ident_f.result() if ident_f is not None else identify(meas)
        ranking, not_fitted = rank_candidates(session, names, second, verbose, ident, progress)
        ranking, not_fitted = with_alternatives(session, ranking, not_fitted, ident, verbose, progress)
        if ranked is not None:
            ranked(base, base_cmp, tuple(ranking), session.test)
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
        also = None if taps else also_explaining(mechanism_classes("+".join(ranking[0].effects)), ident.output_candidates)
        if also:  # said, not hidden: the explanation is one of several the output allows
            reasons = list(reasons) + [also]
            line += "; " + also
    names_baseline = bool(explained and base_cmp.p_value >= ALPHA and not flagged)
    # ---- the models the data cannot tell apart (lab/_ambiguity.py), and the
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
    session = Session.create(key, meas, shots)
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
        session = Session.create(key, meas, shots)
        model, cmp, scored, fitted = session.baseline, session.baseline_comparison, session.test_meas, True
        k_step = session.k_step
    else:
        _, _, k_cmp, k_ref, k_step = jax.random.split(key, 5)
        model, scored, fitted = Model(physics), meas, False
        cmp = compare(k_cmp, model, meas, shots=shots, ref=reference(k_ref, meas))
    where = one_step_check(k_step, model, meas) if meas.has_taps else []
    return {"model": model, "fitted": fitted, "comparison": cmp, "scored": scored, "where": where}
