"""Job functions of the sweeps: one grid point in, a dict of numbers out.

Each job is a module-level function (picklable, importable by Dask workers) that calls the
library's public API; nothing here re-implements the science.

* :func:`gift_job` -- one fine-tuning run, ``gift_theory.finetune.run_finetune`` (reference §4
  finetune keys), for GIFT or any rival method, with the true noise of the simulated chip
  given in the paper's parametrisation (:func:`true_noise`).
* :func:`estimator_job` -- one estimate of d/ds grad J by ``gift_theory.estimators.d_ds_grad``
  and its relative error against a high-precision reference.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os

import numpy as np

#: the true-noise laws of fig:performance_gift_violated_noise_assumption, plus the baseline
NOISE_KINDS = ("awgn", "laplace", "multiplicative", "uniform")


def needs(what: str, why: str) -> RuntimeError:
    """The error raised when a figure's input (another part of gift) is not available."""
    return RuntimeError(f"needs {what} ({why}); it is not available in this checkout")


def true_noise(noise_kind: str, st: float) -> tuple[float, tuple[str, ...]]:
    """Map the paper's true-noise law with parameter ``st`` onto reference §2 effects.

    The paper (Section "GIFT's performance when the noise is not AWGN") uses
    a) U(-st, st), b) multiplicative Gaussian with standard deviation st, c) Laplace(0, st).
    Our effects are parametrised by their standard deviation s, so:

    ==============  ==========================  ===============================================
    noise_kind      paper's law                  chip physics
    ==============  ==========================  ===============================================
    awgn            N(0, st^2)                   awgn s = st
    uniform         U(-st, st), std st/sqrt(3)   awgn s = st / sqrt(3) + ``uniform``
    laplace         Laplace(0, st), std st*√2    awgn s = st * sqrt(2) + ``laplace``
    multiplicative  g = 1 + st xi                awgn s = 0 (additive noise off) + multiplicative m = st
    ==============  ==========================  ===============================================

    Returns
    -------
    (s_true, true_effects) : the chip's awgn level and the extra effects as ``NAME[=VALUE]``.
    """
    st = float(st)
    if noise_kind == "awgn":
        return st, ()
    if noise_kind == "uniform":
        return st / math.sqrt(3.0), ("uniform",)
    if noise_kind == "laplace":
        return st * math.sqrt(2.0), ("laplace",)
    if noise_kind == "multiplicative":
        return 0.0, (f"multiplicative={st:.12g}",)
    raise ValueError(f"noise_kind {noise_kind!r} unknown; known: {', '.join(NOISE_KINDS)}")


def prediction_level(s_true: float, st: float) -> float:
    """The AWGN level of Theorem 1's in-silico prediction: the chip's additive noise standard
    deviation (the multiplicative law has none: AWGN at the paper's st stands in for it)."""
    return float(s_true) if s_true > 0 else float(st)


def _run_finetune():
    try:
        from gift_theory.finetune import run_finetune
    except ImportError as exc:
        raise needs("gift_theory.finetune.run_finetune", "the GIFT issue's job function") from exc
    return run_finetune


#: the variants of issue 25 at the key cells: name -> (finetune method, its options). gift
#: without its confirmation and with a 5x chip budget; Algorithm 1 (gift-printed) with eta a
#: fraction of |w0|, as printed (w0 not a candidate) and with w0 in its selection (as the
#: paper's text says); the retrain oracle and its control, the same retraining at s0 (no
#: mismatch: the gain of extra training alone)
VARIANTS = {
    "gift": ("gift", {}),
    "gift-noconfirm": ("gift", {"confirm": False}),
    "gift-budget100": ("gift", {"budget": 100}),
    **{f"printed-eta{e:g}": ("gift-printed", {"rel_step": e / 100}) for e in (0.05, 0.1, 0.3, 1)},
    **{f"printed-w0-eta{e:g}": ("gift-printed", {"rel_step": e / 100, "keep_w0": True}) for e in (0.05, 0.1, 0.3, 1)},
    "retrain": ("retrain", {}),
    "retrain-s0": ("retrain", {"at": "s0"}),
}


def _run_ceiling():
    try:
        from gift_theory.finetune import run_ceiling
    except ImportError as exc:
        raise needs("gift_theory.finetune.run_ceiling", "issue 25's ceiling of the GIFT line") from exc
    return run_ceiling


def gift_job(net: str, s0: float, st: float, seed: int, *, arch: str, noise_kind: str = "awgn",
             method: str = "gift", dataset: str = "digits", options: dict | None = None,
             train_epochs: int | None = None, variant: str | None = None, **dims) -> dict:
    """One point of a fine-tuning sweep.

    Parameters
    ----------
    net : a label of the architecture (``deep``/``shallow``), a grid dimension
    arch : the widths, e.g. ``"64-48-32-32-16-10"`` (passed to run_finetune)
    s0 : training noise level; st : true noise parameter in the paper's parametrisation
    seed : names the in-silico training run and the fine-tuning randomness
    noise_kind : see :func:`true_noise`
    method : a reference §4 finetune method, or a name of :data:`VARIANTS` (as ``variant``)
    options : extra keyword arguments for ``run_finetune`` (K1, K2, eta, mnist folder, ...)
    train_epochs : train w0 for this many epochs instead of the default recipe's
    variant : a name of :data:`VARIANTS` (replaces ``method`` and adds its options)

    Returns
    -------
    dict : the numeric reference §4 keys (loss/accuracy before/after on train and test,
    in_situ_evaluations, seconds), ``s_true`` (the chip's awgn level after the mapping), the
    referee's standard errors (``loss_before_se``, ..., ``loss_change_se``), whether the line
    search's confirmation ``accepted``, for line-search methods Theorem 1's prediction
    against the realised change (``predicted_change``, ``realised_change``, ... see
    :mod:`gift_theory.finetune._predict`), and the wall seconds of each phase
    (``seconds_setting``: training or loading w0; ``seconds_method``; ``seconds_referee``; ...)
    with ``seconds_compiling``, the part JAX spent compiling; for line searches and Algorithm 1
    ``kept_w0``, ``confirmation_z``, ``predicted_gain`` and ``predicted_gain_pct`` (``gift_info``).
    """
    s_true, effects = true_noise(noise_kind, st)
    run_finetune = _run_finetune()
    opts = dict(options or {})
    if variant is None and method in VARIANTS:  # e.g. gift-noconfirm in a sweep's method dim
        variant = method
    if variant is not None:
        if variant not in VARIANTS:
            raise ValueError(f"variant {variant!r} unknown; known: {', '.join(VARIANTS)}")
        method, extra = VARIANTS[variant]
        opts.update(extra)
    if train_epochs is not None:
        opts["train_epochs"] = int(train_epochs)
    opts.setdefault("predict_s", prediction_level(s_true, st))
    from gift_theory import memo as _memo
    from gift_theory.profiling import PhaseClock

    if _memo.folder() is None:  # share the in-silico part with the other points, on any worker
        from gift_theory.training import cache_dir

        _memo.use_folder(os.path.join(cache_dir(), "memo"))
    memo_before = _memo.counters()
    with PhaseClock() as clock:  # where the point's time went: setting (training or loading), method, referee
        res = run_finetune(dataset=dataset, arch=arch, s0=float(s0), st=s_true, true_effects=effects, method=method,
                           seed=int(seed), **opts)
    # "s0"/"st" are grid dimensions here; run_finetune's "st" is the chip's awgn level, kept as s_true
    info = res.get("info", {})
    gi = res.get("gift_info") or {}
    flat = dict(res, **info.get("referee", {}), **info.get("prediction", {}),
                **{k: v for k, v in gi.items() if k != "reason"})
    if "accepted" in info:
        flat["accepted"] = bool(info["accepted"])
    out = {k: v for k, v in flat.items()
           if isinstance(v, (int, float, bool, np.number)) and not isinstance(v, str) and k not in ("s0", "st")}
    return _with_costs(out, s_true, clock, memo_before)


#: the memo tags of in-silico work at s0 that every point with the same (net, s0, seed, method)
#: shares, whatever the chip's noise (the slope at the chip's level is not among them)
SHARED_TAGS = ("direction", "curvature", "pair_se", "slope_s0")


def shared_work(before: dict, after: dict) -> dict:
    """``seconds_shared`` (computing the shared in-silico work this point did not find done),
    ``shared_hits`` and ``shared_misses``, from two :func:`gift_theory.memo.counters`."""
    zero = {"hits": 0, "misses": 0, "seconds_computed": 0.0}
    d = {k: sum(after.get(t, zero)[k] - before.get(t, zero)[k] for t in SHARED_TAGS) for k in zero}
    return {"seconds_shared": float(d["seconds_computed"]), "shared_hits": int(d["hits"]),
            "shared_misses": int(d["misses"])}


# ----------------------------------------------------------------------------- the ceiling
def ceiling_job(net: str, s0: float, st: float, seed: int, *, arch: str, noise_kind: str = "awgn",
                dataset: str = "digits", kinds=("pathwise", "score_paper"), options: dict | None = None,
                train_epochs: int | None = None, **dims) -> dict:
    """The referee's best along the GIFT line w0 + a u at one point
    (:func:`gift_theory.finetune.run_ceiling`): for each direction kind the step with the
    lowest training loss and the one with the highest training accuracy, scored on training
    and test data, and w0's numbers on the same draws.

    ``options`` are the fine-tuning sweeps' (only ``referee_K2``, ``K1``, ``K2`` and ``data_folder``
    matter here: the same w0, the same problem key, so the same memoized directions);
    ``train_epochs`` as in :func:`gift_job`.

    Returns
    -------
    dict of numbers: ``loss_before`` ... ``test_accuracy_before``, per kind ``<kind>_loss``,
    ``<kind>_accuracy``, ``<kind>_test_loss``, ``<kind>_test_accuracy``,
    ``<kind>_accuracy_best``, ``<kind>_test_accuracy_at_best``, ``<kind>_rel_step_loss``,
    ``<kind>_rel_step_acc``, ``<kind>_at_edge``; ``cos_<kind>_gradient`` with the gradient
    among the kinds; the phases' seconds as in :func:`gift_job`.
    """
    from gift_theory import memo as _memo
    from gift_theory.profiling import PhaseClock

    run_ceiling = _run_ceiling()
    s_true, effects = true_noise(noise_kind, st)
    opts = {k: v for k, v in (options or {}).items() if k in ("referee_K2", "K1", "K2", "data_folder")}
    if _memo.folder() is None:
        from gift_theory.training import cache_dir

        _memo.use_folder(os.path.join(cache_dir(), "memo"))
    memo_before = _memo.counters()
    with PhaseClock() as clock:
        res = run_ceiling(dataset=dataset, arch=arch, s0=float(s0), st=s_true, true_effects=effects, seed=int(seed),
                          kinds=tuple(kinds), train_epochs=train_epochs, **opts)
    out = {k: v for k, v in res.items()
           if isinstance(v, (int, float, bool, np.number)) and k not in ("s0", "st")}
    return _with_costs(out, s_true, clock, memo_before)


# ----------------------------------------------------------------------------- estimators
@functools.lru_cache(maxsize=4)
def _estimator_problem(dataset: str, arch: str, s0: float, seed: int, ref_K2: int, train_epochs: int | None = None):
    """Trained weights, the training data and a reference d/ds grad J (pathwise, all inputs,
    ``ref_K2`` draws each); cached per worker process."""
    import jax

    import gift_theory as gt
    from gift_theory.data import load_dataset
    from gift_theory.estimators import d_ds_grad
    from gift_theory.training import default_config, load_or_train

    a = gt.Architecture.parse(arch)
    config = default_config(dataset, a)
    if train_epochs is not None:  # short training for the test suite's tiny scale
        config = dataclasses.replace(config, epochs=int(train_epochs))
    params, _ = load_or_train(dataset, a, s0=s0, seed=seed, config=config, progress=False)
    ds = load_dataset(dataset)
    phys = gt.awgn(s0)
    ref = d_ds_grad(jax.random.PRNGKey(10_007), params, ds.x_train, ds.y_train, phys, a, method="pathwise",
                    K2=ref_K2)
    ref_vec = np.asarray(gt.flatten(ref.mean)[0], np.float64)
    ref_se = np.asarray(gt.flatten(ref.se)[0], np.float64)
    return a, params, ds, phys, ref_vec, ref_se


def estimator_job(method: str, K1: int, K2: int, rep: int, *, dataset: str = "digits", arch: str = "64-32-32-10",
                  s0: float = 0.1, seed: int = 0, ref_K2: int = 64, train_epochs: int | None = None,
                  **dims) -> dict:
    """Relative error of one d/ds grad J estimate with K1 inputs (drawn with replacement from the
    training set) and K2 draws each, against the reference.

    ``score_paper`` (D^[0] as printed) targets -(s/2) d/ds grad J, not d/ds grad J; it is
    reported twice: ``rel_error`` as printed, ``rel_error_rescaled`` divided by that constant.

    Returns
    -------
    dict with ``rel_error``, ``rel_error_rescaled``, ``rel_error_debiased`` (rescaled, with the
    reference's own variance subtracted: sqrt(max(|est - ref|^2 - |se_ref|^2, 0)) / |ref|), ``rel_se`` (the estimate's own standard
    error, relative) and ``ref_rel_se`` (the reference's, the floor of measurable error).
    """
    import jax

    import gift_theory as gt
    from gift_theory.estimators import d_ds_grad, paper_constant

    a, params, ds, phys, ref_vec, ref_se = _estimator_problem(dataset, arch, float(s0), int(seed), int(ref_K2),
                                                            train_epochs)
    key = jax.random.fold_in(jax.random.fold_in(jax.random.PRNGKey(int(seed)), int(rep)), int(K1) * 1000 + int(K2))
    k_data, k_est = jax.random.split(key)
    idx = np.asarray(jax.random.randint(k_data, (int(K1),), 0, ds.x_train.shape[0]))
    est = d_ds_grad(k_est, params, ds.x_train[idx], ds.y_train[idx], phys, a, method=method, K2=int(K2),
                    groups=min(32, int(K1)))
    vec = np.asarray(gt.flatten(est.mean)[0], np.float64)
    se = np.asarray(gt.flatten(est.se)[0], np.float64)
    norm = float(np.linalg.norm(ref_vec))
    c = paper_constant(s0) if method == "score_paper" else 1.0
    ref_var = float(np.sum(ref_se**2))

    def debiased(v):
        # E|est - ref|^2 = E|est - truth|^2 + E|ref - truth|^2 (independent draws): remove the reference's part
        return float(np.sqrt(max(np.sum((v - ref_vec) ** 2) - ref_var, 0.0)) / norm)

    return {"rel_error": float(np.linalg.norm(vec - ref_vec) / norm),
            "rel_error_rescaled": float(np.linalg.norm(vec / c - ref_vec) / norm),
            "rel_error_debiased": debiased(vec / c),
            "rel_se": float(np.linalg.norm(se / abs(c)) / norm),
            "ref_rel_se": float(np.linalg.norm(ref_se) / norm),
            "samples": int(K1) * int(K2)}


def unavailable(job: str, fixed: dict | None = None) -> str | None:
    """Why ``job`` cannot run in this checkout (a missing input), or None; checked once per sweep
    so that a missing dependency is one message, not one failure per point."""
    if job.endswith(":gift_job") or job.endswith(":ceiling_job"):
        try:
            from gift_theory.finetune import run_finetune  # noqa: F401
        except ImportError:
            return "needs gift_theory.finetune.run_finetune (the GIFT issue's job function)"
        if "data_folder" in (fixed or {}).get("options", {}):
            import inspect

            from gift_theory.finetune import run_ceiling, run_finetune

            fn = run_ceiling if job.endswith(":ceiling_job") else run_finetune
            if "data_folder" not in inspect.signature(fn).parameters:
                return (f"needs {fn.__name__}(data_folder=...) for an MNIST IDX folder; use mnist5k (the default "
                        f"of --scale paper) meanwhile")
    if job.endswith(":estimator_job"):
        try:
            from gift_theory.estimators import d_ds_grad  # noqa: F401
        except ImportError:
            return "needs gift_theory.estimators.d_ds_grad"
    return None


def _with_costs(out: dict, s_true: float, clock, memo_before) -> dict:
    """A point's numbers plus the chip's true s, each top-level phase's seconds, the compile
    seconds and the in-silico work it shared with earlier points."""
    from gift_theory import memo as _memo  # imported in the job, as the workers do

    out["s_true"] = s_true
    for name, p in clock.phases.items():
        if "/" not in name:
            out[f"seconds_{name}"] = p["seconds"]
    out["seconds_compiling"] = sum(p["compile_seconds"] for n, p in clock.phases.items() if "/" not in n)
    out.update(shared_work(memo_before, _memo.counters()))
    return out
