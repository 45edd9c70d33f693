"""Job functions of the sweeps: one grid point in, a dict of numbers out.

Each job is a module-level function (picklable, importable by Dask workers) that calls the
library's public API; nothing here re-implements the science.

* :func:`gift_job` -- one fine-tuning run, ``gift_theory.finetune.run_finetune`` (CONTRACTS §4
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
    """Map the paper's true-noise law with parameter ``st`` onto CONTRACTS §2 effects.

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


def gift_job(net: str, s0: float, st: float, seed: int, *, arch: str, noise_kind: str = "awgn",
             method: str = "gift", dataset: str = "digits", options: dict | None = None, **dims) -> dict:
    """One point of a fine-tuning sweep.

    Parameters
    ----------
    net : a label of the architecture (``deep``/``shallow``), a grid dimension
    arch : the widths, e.g. ``"64-48-32-32-16-10"`` (passed to run_finetune)
    s0 : training noise level; st : true noise parameter in the paper's parametrisation
    seed : names the in-silico training run and the fine-tuning randomness
    noise_kind : see :func:`true_noise`
    method : a CONTRACTS §4 finetune method
    options : extra keyword arguments for ``run_finetune`` (K1, K2, eta, mnist folder, ...)

    Returns
    -------
    dict : the numeric CONTRACTS §4 keys (loss/accuracy before/after on train and test,
    in_situ_evaluations, seconds), ``s_true`` (the chip's awgn level after the mapping), the
    referee's standard errors (``loss_before_se``, ..., ``loss_change_se``), whether the line
    search's confirmation ``accepted``, for line-search methods Theorem 1's prediction
    against the realised change (``predicted_change``, ``realised_change``, ... see
    :mod:`gift_theory.finetune._predict`), and the wall seconds of each phase
    (``seconds_setting``: training or loading w0; ``seconds_method``; ``seconds_referee``; ...)
    with ``seconds_compiling``, the part JAX spent compiling.
    """
    s_true, effects = true_noise(noise_kind, st)
    run_finetune = _run_finetune()
    opts = dict(options or {})
    opts.setdefault("predict_s", prediction_level(s_true, st))
    from gift_theory import _memo
    from gift_theory._phases import PhaseClock

    if _memo.folder() is None:  # share the in-silico part with the other points, on any worker
        from gift_theory.training import cache_dir

        _memo.use_folder(os.path.join(cache_dir(), "memo"))
    memo_before = _memo.counters()
    with PhaseClock() as clock:  # where the point's time went: setting (training or loading), method, referee
        res = run_finetune(dataset=dataset, arch=arch, s0=float(s0), st=s_true, true_effects=effects, method=method,
                           seed=int(seed), **opts)
    # "s0"/"st" are grid dimensions here; run_finetune's "st" is the chip's awgn level, kept as s_true
    info = res.get("info", {})
    flat = dict(res, **info.get("referee", {}), **info.get("prediction", {}))
    if "accepted" in info:
        flat["accepted"] = bool(info["accepted"])
    out = {k: v for k, v in flat.items()
           if isinstance(v, (int, float, bool, np.number)) and not isinstance(v, str) and k not in ("s0", "st")}
    out["s_true"] = s_true
    for name, p in clock.phases.items():
        if "/" not in name:
            out[f"seconds_{name}"] = p["seconds"]
    out["seconds_compiling"] = sum(p["compile_seconds"] for n, p in clock.phases.items() if "/" not in n)
    out.update(shared_work(memo_before, _memo.counters()))
    return out


#: the memo tags of in-silico work at s0 that every point with the same (net, s0, seed, method)
#: shares, whatever the chip's noise (the slope at the chip's level is not among them)
SHARED_TAGS = ("direction", "curvature", "pair_se", "slope_s0")


def shared_work(before: dict, after: dict) -> dict:
    """``seconds_shared`` (computing the shared in-silico work this point did not find done),
    ``shared_hits`` and ``shared_misses``, from two :func:`gift_theory._memo.counters`."""
    zero = {"hits": 0, "misses": 0, "seconds_computed": 0.0}
    d = {k: sum(after.get(t, zero)[k] - before.get(t, zero)[k] for t in SHARED_TAGS) for k in zero}
    return {"seconds_shared": float(d["seconds_computed"]), "shared_hits": int(d["hits"]),
            "shared_misses": int(d["misses"])}


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
    if job.endswith(":gift_job"):
        try:
            from gift_theory.finetune import run_finetune  # noqa: F401
        except ImportError:
            return "needs gift_theory.finetune.run_finetune (the GIFT issue's job function)"
        if "folder" in (fixed or {}).get("options", {}):
            import inspect

            from gift_theory.finetune import _run

            if "folder" not in inspect.signature(_run.load_setting).parameters:
                return ("needs run_finetune(folder=...) for an MNIST IDX folder (its load_setting takes no "
                        "folder); use mnist5k (the default of --scale paper) meanwhile")
    if job.endswith(":estimator_job"):
        try:
            from gift_theory.estimators import d_ds_grad  # noqa: F401
        except ImportError:
            return "needs gift_theory.estimators.d_ds_grad"
    return None
