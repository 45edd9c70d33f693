"""What a model with fitted offsets costs, and the null that allows for them.

Its cost is its **effective degrees of freedom**, the trace of the ridge's hat matrix
``sum_k lam_k / (lam_k + sigma^2 / e^2)`` over the eigenvalues ``lam_k`` of ``J^T J``, J the
Jacobian of the fitted means in the offsets: an offset the data pin down counts 1, one the
prior alone sets counts 0. With taps the Jacobian of each layer is block diagonal over its
output neurons (a neuron's offsets move that neuron only), so it costs a few passes of the
layer; without taps it is the full Jacobian of the output means.

Its p-value is taken against a **refit null** (:func:`offset_replicates`): B times, data
simulated from the fitted model as the truth, the offsets refitted, the refitted model
scored on simulated held-out data.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .. import _random
from .._measurement import Measurement
from .._model import (
    forward,
    named_subkey,
    simulate,
)
from .._process import release_freed_memory
from ._budget import map_in_threads
from ._shots import Model, padded_rows, params32, to32
from ._offset_kinds import (
    _initial_scale,
    _split_by_kind,
    apply_all,
    base_model,
    fitted_as_offsets,
    kind_columns,
    kinds_of,
    unflat_vector,
)
from ._offset_fit import _forward_with, _joint_setup, _layer_jvps, _layer_setup, estimate_offsets, offset_deltas


#: replicates of the refit null (see :func:`offset_replicates`)
OFFSET_REPLICATES = 8


def effective_dof(key, meas: Measurement, model: Model, kinds) -> tuple[float, int]:
    """``(effective, nominal)`` degrees of freedom of the offsets of ``model`` (module docstring).

    With taps, per layer and output neuron i: the columns of J_i are the changes of neuron i's
    mean prediction per offset of row i (a direction that moves entry j of every row at once
    gives column j of every J_i in one pass). Without taps: the full Jacobian of the output
    means, column by column.
    """
    arch = meas.arch
    e = {k: float(model.offsets.get(k.effect, 0.0)) or _initial_scale(k, model.weights(meas), model.physics)
         for k in kinds}
    p32 = params32(model.weights(meas))
    nominal = sum(int(np.prod(k.shape(arch, l))) for k in kinds for l in k.layers)
    if not meas.has_taps:
        J, inv_v = _output_jacobian(key, meas, model, kinds)
        sig2 = 1.0 / inv_v
        scale = np.concatenate([np.full(int(np.prod(k.shape(arch, l))), e[k] ** 2) for k in kinds for l in k.layers])
        # hat-matrix trace of the ridge with prior covariance diag(scale): eig of S^1/2 J^T J S^1/2 / sig2
        Js = J * np.sqrt(scale)[None, :] / np.sqrt(sig2)
        lam = np.linalg.svd(Js, compute_uv=False) ** 2
        return float(np.sum(lam / (lam + 1.0))), nominal
    total = 0.0
    for l in range(1, arch.depth + 1):
        here = tuple(k for k in kinds if l in k.layers)
        if not here:
            continue
        W, b = p32[l - 1]
        noise, a, t, _, resid_var, axis = _layer_setup(jax.random.fold_in(named_subkey(key, "offsets"), l), meas,
                                                       model.physics, l)
        d_l = arch.widths[l]
        # columns per neuron: each W kind contributes d_in (entry j of every row), b / per-neuron 1
        basis, owner = kind_columns(here, arch, l)
        zero = tuple(np.zeros(k.shape(arch, l), np.float32) for k in here)
        prior = np.array([e[here[o]] ** 2 for o in owner])
        scale = (np.sqrt(prior) / np.sqrt(resid_var))[:, None, None]  # per column: the prior over the noise
        draws = max((int(np.prod(v.shape[1:axis + 1])) for v in jax.tree_util.tree_leaves(noise)), default=1)
        spans, size = input_chunks(meas.n, len(owner) * draws * d_l * 4)
        gram = 0.0
        for i0, i1 in spans:
            part = functools.partial(padded_rows, i0=i0, i1=i1, size=size)
            cols = np.asarray(_layer_jvps(zero, W, b, part(a), jax.tree_util.tree_map(part, noise), model.physics,
                                          None if t is None else part(t), basis, arch, l, axis, here)[1], np.float64)
            cols = cols[:, :i1 - i0].reshape(len(owner), -1, d_l)  # (P_i, samples, neurons)
            # per neuron i, J_i (samples, P_i) scaled by the prior and the noise; the eigenvalues
            # of J_i^T J_i (a P_i x P_i Gram matrix per neuron: the squared singular values of
            # J_i), the Gram summed over the chunks of inputs
            Js = np.ascontiguousarray(np.transpose(cols * scale, (2, 1, 0)))
            del cols
            gram = gram + np.swapaxes(Js, 1, 2) @ Js
            del Js
        lam = np.clip(np.linalg.eigvalsh(gram), 0.0, None)
        total += float(np.sum(lam / (lam + 1.0)))
    return total, nominal


#: bytes of one layer's tangents (directions x inputs x draws x neurons, float32) that
#: :func:`effective_dof` computes at once; a larger measurement is read in chunks of inputs
JVP_CHUNK_BYTES = 96 << 20


def input_chunks(n: int, per_input: int, budget: int | None = None):
    """``(spans, size)``: ``range(n)`` in equal chunks of ``size`` inputs (the last one shorter,
    padded by :func:`~._shots.padded_rows` so that one compiled program serves every chunk) of at most
    ``budget`` bytes (default :data:`JVP_CHUNK_BYTES`) at ``per_input`` bytes an input; one
    chunk, unpadded, when all fit."""
    budget = JVP_CHUNK_BYTES if budget is None else budget
    k = max(1, -(-n * int(per_input) // int(budget)))
    size = -(-n // k)
    return [(i, min(i + size, n)) for i in range(0, n, size)], size


def _output_jacobian(key, meas: Measurement, model: Model, kinds, chunk: int = 64):
    """J (n d_L, P) of the model's mean outputs in every offset, and the inverse variance of a
    measured mean (no taps)."""
    arch = meas.arch
    K, noise, t, _, _ = _joint_setup(named_subkey(key, "jacobian"), meas, model.physics)
    x = to32(meas.x)
    p32 = params32(model.weights(meas))
    shapes = tuple(k.shape(arch, l) for k in kinds for l in k.layers)
    P = sum(int(np.prod(s)) for s in shapes)
    cols = []
    for i in range(0, P, chunk):
        basis = np.zeros((min(chunk, P - i), P), np.float32)
        basis[np.arange(basis.shape[0]), i + np.arange(basis.shape[0])] = 1.0
        cols.append(np.asarray(_mean_output_jvp(p32, x, noise, model.physics, t, jnp.asarray(basis), arch, shapes,
                                                kinds), np.float64))
    J = np.concatenate(cols, axis=0).T
    Y = meas.layers()[-1]
    inv_v = meas.r / max(float(np.mean(np.var(Y, axis=1))), 1e-12)
    return J, inv_v


@functools.partial(jax.jit, static_argnames=("arch", "shapes", "kinds"))
def _mean_output_jvp(p32, x, noise, physics, t, basis, arch, shapes, kinds):
    def f(flat):
        deltas = _split_by_kind(unflat_vector(flat, shapes), kinds)
        return jnp.mean(_forward_with(deltas, kinds, p32, x, noise, physics, t, arch)[-1], axis=1).ravel()

    zero = jnp.zeros(basis.shape[1], jnp.float32)
    return jax.vmap(lambda v: jax.jvp(f, (zero,), (v,))[1])(basis)


def resimulate(key, model: Model, meas: Measurement) -> Measurement:
    """``meas`` with its shots (and taps) replaced by shots of ``model`` taken as the truth:
    same inputs, shots per input, times and programmed weights."""
    t = None if meas.t is None else to32(meas.t)
    out = simulate(key, params32(model.weights(meas)), to32(meas.x), model.physics, meas.arch,
                   shots=meas.r, t=t, taps=True)
    taps = tuple(np.asarray(a, np.float64) for a in out.taps[:-1]) if meas.has_taps else None
    return dataclasses.replace(meas, y=np.asarray(out.y, np.float64), taps=taps)


def marginal_e2(d2, c2, sigma2: float) -> float:
    """Empirical-Bayes e^2: the maximiser of the Gaussian marginal likelihood of a whitened
    residual ``rho ~ N(0, e^2 Jw Jw^T + sigma2 I)``, given the squared singular values ``d2``
    of Jw and the squared coordinates ``c2`` of rho in its left singular basis: they have
    variances e^2 d_k^2 + sigma2, so every direction weighs in by its own precision (the
    plain moment equation |rho|^2 = e^2 tr(Jw^T Jw) + n sigma2 is ruled by the largest d_k:
    on a 6-10-4 file without taps, true e = 0.15, it gives 0.08 where this gives 0.13)."""
    def nll(log_e2):
        v = np.exp(log_e2) * d2 + sigma2
        return 0.5 * float(np.sum(np.log(v) + c2 / v))

    if not np.any(d2 > 0):
        return 0.0
    top = np.log(float(np.sum(c2)) + sigma2) - np.log(float(np.min(d2[d2 > 0])))
    res = optimize.minimize_scalar(nll, bounds=(top - 60.0, top), method="bounded")
    return float(np.exp(res.x))


def _posterior_spread(key, model: Model, base: Model, meas: Measurement, kinds, K: int = 32):
    # base: :func:`base_model` of ``model``
    """A square root S of the offsets' posterior covariance from the output means (no taps),
    linearised at the fit: with J the Jacobian of the model's mean outputs in the offsets and
    v the inverse variance of a measured mean, ``S S^T = (v J^T J + diag(1 / e^2))^-1``.

    e is the empirical-Bayes scale (:func:`marginal_e2` on r0, the residual of the base
    model's mean outputs; the model's K-draw mean adds r/K to the measured means' variance),
    not the fitted one: the ridge sets the unidentified directions to zero, so the rms of
    the offsets underestimates e (0.09 for a true 0.15 on 8-16-8-4). Never below the fitted e.
    A single kind shares one e; several kinds scale theirs by the same factor."""
    arch, r = meas.arch, meas.r
    J, v = _output_jacobian(key, meas, model, kinds)
    _, noise, t, _, _ = _joint_setup(named_subkey(key, "jacobian"), meas, model.physics)
    Y = meas.layers()[-1]
    target = np.mean(Y, axis=1).ravel()
    base_out = _mean_output(params32(base.weights(meas)), to32(meas.x), noise, base.physics, t, arch)
    r0 = target - np.asarray(base_out, np.float64).ravel()
    e_fit = np.concatenate([np.full(int(np.prod(k.shape(arch, l))), float(model.offsets.get(k.effect, 1e-3)))
                            for k in kinds for l in k.layers])
    Js = J * e_fit[None, :]  # in units of the fitted scales
    U, d, _ = np.linalg.svd(np.sqrt(v) * Js, full_matrices=False)
    factor2 = max(marginal_e2(d ** 2, (U.T @ (np.sqrt(v) * r0)) ** 2, 1.0 + r / K), 1.0)
    prior = factor2 * e_fit ** 2
    lam, Wv = np.linalg.eigh(v * (J.T @ J) + np.diag(1.0 / prior))
    return Wv * (1.0 / np.sqrt(np.maximum(lam, 1e-300)))[None, :]


def _mean_out(p32, x, noise, physics, t, arch):
    return jnp.mean(forward(p32, x[:, None, :], noise, physics, arch, t=t).y, axis=1)


_mean_output = jax.jit(_mean_out, static_argnames=("arch",))


def offset_replicates(key, model: Model, fit_meas: Measurement, test_meas: Measurement, ref, *,
                      channel_values, shots: int | None = None, B: int = OFFSET_REPLICATES,
                      workers: int = 1) -> np.ndarray:
    """Channel values of a model with fitted offsets under the null *with* its estimation
    error, for :func:`~gift_theory.lab.compare`'s ``null_replicates``: B times, data are
    simulated from the fitted model as the truth on the fitting inputs, the offsets refitted
    (the same estimator, with the model's scales, from the fitted values), and the refitted
    model scored on data simulated on the held-out inputs.

    With taps every layer's offsets are identified and the fitted model stands for the truth;
    without taps most directions are not, and each replicate's truth is drawn from the
    offsets' posterior (the part the data cannot see, at its full size).

    ``workers`` threads make the replicates at once (the same numbers for any number).

    Returns
    -------
    (B, n_test, L', C) array
    """
    kinds = kinds_of([n for n in model.offsets if fitted_as_offsets(n)], fit_meas.arch)
    if not kinds:
        raise ValueError("offset_replicates: the model has no fitted offsets")
    arch = fit_meas.arch
    base = base_model(model, fit_meas)
    fitted = offset_deltas(model, base, fit_meas, kinds)
    scales = {k: float(model.offsets[k.effect]) for k in kinds}
    spread = (None if fit_meas.has_taps
              else _posterior_spread(named_subkey(key, "posterior"), model, base, fit_meas, kinds))
    shapes = [k.shape(arch, l) for k in kinds for l in k.layers]

    def replicate(b):
        kb = jax.random.fold_in(key, b)
        k_tr, k_te, k_fit, k_cmp, k_truth = (named_subkey(kb, s) for s in ("fit_data", "test_data", "refit", "score",
                                                                            "truth"))
        truth = model
        if spread is not None:
            z = spread @ np.asarray(_random.normal_like_jax(k_truth, (spread.shape[1],)), np.float64)
            flat = np.concatenate([np.ravel(a) for k in kinds for a in fitted[k]]) + z
            deltas = _split_by_kind(unflat_vector(flat, shapes), kinds)
            p, ph = apply_all(kinds, deltas, base.weights(fit_meas), base.physics, arch)
            truth = Model(ph, p, model.offsets)
        sim_tr = resimulate(k_tr, truth, fit_meas)
        deltas = estimate_offsets(k_fit, sim_tr, base.physics, base.weights(fit_meas), kinds, scales, start=fitted)
        p, ph = apply_all(kinds, deltas, base.weights(fit_meas), base.physics, arch)
        refit = Model(ph, p, model.offsets)
        out = channel_values(k_cmp, refit, resimulate(k_te, truth, test_meas), ref, shots)
        release_freed_memory()  # a replicate's simulated campaigns, not kept for the next
        return out

    # the replicates are independent (each from its own subkey): ``workers`` threads make them at once
    return np.stack(map_in_threads(replicate, range(B), workers))
