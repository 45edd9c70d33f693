"""Trained weights saved once and reused: a cache keyed by everything that shapes them.

A weight file is an ``.npz`` with ``W1..WL, b1..bL`` (the reference §3 names) and the
metadata ``arch, activation, s0, seed, dataset, method, steps, config`` plus the train
and test metrics measured when it was made. Files are written to a temporary name and
renamed, so a killed run never leaves half a file.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time

import jax
import numpy as np

from .._arch import Architecture
from .._cachedir import cache_dir, unwritable, warn_once
from .._errors import GiftInputError, require
from .._io import atomic_write
from .._objective import estimate_from_samples, per_input_scores
from .._params import params_from_arrays, params_to_arrays
from .._phases import phase
from ..effects import Physics, awgn
from ._sgd import TrainConfig, stderr_progress, train




def default_config(dataset: str, arch: Architecture) -> TrainConfig:
    """The training recipe used unless told otherwise (measured: digits 64-32-32-10 at s0 = 0.1
    reaches ~97 % test accuracy in 60 epochs; mnist5k 784-500-100-100-10 ~91 % in 30)."""
    if arch.widths[0] > 100:
        return TrainConfig(epochs=30, lr=0.005, momentum=0.9, batch_size=32)
    return TrainConfig(epochs=60, lr=0.05, momentum=0.9, batch_size=32)


def cache_key(dataset: str, arch: Architecture, s0: float, seed: int, config: TrainConfig,
              physics: Physics | None = None) -> str:
    spec = {"dataset": dataset, "widths": list(arch.widths), "activation": arch.activation,
            "noise_sites": arch.noise_sites, "s0": float(s0), "seed": int(seed), "config": config.to_json(),
            "physics": None if physics is None else physics.describe()}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]


def save_weights(path: str, params, meta: dict) -> None:
    """Write weights and metadata atomically (temp file in the same folder, then rename)."""
    arrays = params_to_arrays(params)
    arrays["meta_json"] = np.asarray(json.dumps(meta))
    atomic_write(path, lambda fh: np.savez(fh, **arrays))


def load_weights(path: str):
    """``(params, meta)`` from a weight file written by :func:`save_weights` (or any npz with W1, b1, ...)."""
    require(os.path.isfile(path), f"{path}: no such weight file")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as f:  # our handle: closed on a bad file
            arrays = {k: f[k] for k in f.files}
    except Exception as exc:  # zip errors, truncated files
        raise GiftInputError(f"{path}: not a readable .npz file ({type(exc).__name__})") from None
    meta = json.loads(str(arrays.pop("meta_json"))) if "meta_json" in arrays else {}
    return params_from_arrays(arrays, where=path), meta


def evaluate(key, params, ds, physics: Physics, arch: Architecture, K2: int = 4) -> dict:
    """Train/test loss and accuracy (noisy, at ``physics``) with standard errors; loss and
    accuracy of a split come from one pass over the same draws."""
    out = {}
    for split in ("train", "test"):
        x, y, lab = getattr(ds, f"x_{split}"), getattr(ds, f"y_{split}"), getattr(ds, f"labels_{split}")
        losses, correct = per_input_scores(jax.random.fold_in(key, 0), [params], x, y, lab, physics, arch, K2)
        j, a = estimate_from_samples(losses[0]), estimate_from_samples(correct[0])
        out[f"{split}_loss"], out[f"{split}_loss_se"] = float(j.mean), float(j.se)
        out[f"{split}_accuracy"], out[f"{split}_accuracy_se"] = float(a.mean), float(a.se)
    return out


def load_or_train(dataset: str, arch: Architecture, s0: float, seed: int = 0, *, config: TrainConfig | None = None,
                  physics: Physics | None = None, folder: str | None = None, cache: str | None = None,
                  force: bool = False, progress: bool = True):
    """Weights trained in silico at noise level ``s0`` -- from the cache if they exist.

    Parameters
    ----------
    dataset : a :func:`gift_theory.data.load_dataset` name
    arch : Architecture (its d_0 and d_L must match the data)
    s0 : the assumed noise level (awgn) used in training
    seed : names the initialisation and the sampling
    config : TrainConfig (default :func:`default_config`)
    physics : train under this physics instead of ``awgn(s0)`` (advanced)
    folder : the MNIST IDX folder for ``dataset="mnist"``
    cache : cache folder (default :func:`cache_dir`)
    force : retrain even if cached

    Returns
    -------
    params : tuple of Layer
    info : dict with ``path`` (None when the cache could not be written: one warning on stderr),
        ``cached``, ``seconds`` and the train/test metrics (a cached file that cannot be read is
        trained again and rewritten)
    """
    from ..data import load_dataset

    require(s0 >= 0, f"s0={s0} must be non-negative")
    ds = load_dataset(dataset, folder=folder)
    require(arch.widths[0] == ds.n_inputs and arch.widths[-1] == ds.n_outputs,
            f"architecture {arch} does not fit dataset {dataset} (inputs {ds.n_inputs}, outputs {ds.n_outputs})")
    config = config or default_config(dataset, arch)
    physics = physics or awgn(s0)
    key = cache_key(dataset if dataset != "mnist" else f"mnist:{os.path.abspath(folder)}", arch, s0, seed, config,
                    None if physics == awgn(s0) else physics)
    path = os.path.join(cache or cache_dir(), f"{dataset}_{arch}_s{s0:g}_seed{seed}_{key}.npz")
    if os.path.isfile(path) and not force:
        try:
            params, meta = load_weights(path)
            return params, dict(meta, path=path, cached=True)
        except GiftInputError as exc:  # a truncated or damaged entry: trained again and rewritten
            warn_once("broken entry", f"the cached weights are unreadable ({exc}); training again")
    t0 = time.perf_counter()
    label = f"train {dataset} {arch} s0={s0:g} seed={seed}"
    if progress:
        sys.stderr.write(f"{label}: training ({config.method}) on {ds.x_train.shape[0]} examples "
                         f"({ds.x_test.shape[0]} held out for testing) ...\n")
    with phase("train"):
        params = train(jax.random.PRNGKey(seed), arch, ds.x_train, ds.y_train, physics, config,
                       progress=stderr_progress(label) if progress else None)
    seconds = time.perf_counter() - t0
    with phase("train_evaluate"):
        metrics = evaluate(jax.random.PRNGKey(10_000 + seed), params, ds, physics, arch)
    meta = {"dataset": dataset, "arch": str(arch), "activation": arch.activation, "noise_sites": arch.noise_sites,
            "s0": float(s0), "seed": int(seed), "method": config.method, "config": config.to_json(),
            "steps": int(config.steps if config.method == "projected_sgd"
                         else config.epochs * (ds.x_train.shape[0] // config.batch_size)),
            "physics": physics.describe(), "train_seconds": seconds,
            "train_examples": int(ds.x_train.shape[0]), "test_examples": int(ds.x_test.shape[0]), **metrics}
    try:
        save_weights(path, params, meta)
    except OSError as exc:  # a read-only or full cache: the weights are still returned (and --out written)
        unwritable(os.path.dirname(path), exc, "the trained weights")
        path = None
    return params, dict(meta, path=path, cached=False)
