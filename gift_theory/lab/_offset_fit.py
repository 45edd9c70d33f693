"""Fixed offsets estimated from the shots (the kinds: :mod:`._offset_kinds`).

They are estimated with a Gaussian prior (ridge; the scale re-estimated once from the first
pass) through the core's differentiable layer map -- by L-BFGS, or, on a layer (taps) whose
offsets are all one value per neuron, by a Levenberg-Marquardt step per neuron
(:func:`_neuron_lm`: a few steps instead of some 30 gradient evaluations):

* with taps, layer by layer: each layer's measured output shot by shot against the model's
  mean response to the *measured* output of the layer before (layer 1: means over shots
  against the mean response to x); with weight offsets the start is where the layer-wise
  identification puts them (:func:`identified_start`);
* without taps, every layer at once from the output means.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .._measurement import Measurement
from .._model import (
    compiled_draws,
    layer_step,
    named_subkey,
    noisy_input,
)
from .._process import release_freed_memory
from ._shots import Model, _step_sites, params32, tiled_times, to32
from ._offset_kinds import _initial_scale, _split_by_kind, apply_all, apply_layer, kinds_of, reset, unflat_vector


def _lbfgs(value_and_grad, shapes, iters: int = 300, start=None):
    """Minimise a function of a list of arrays of ``shapes`` by L-BFGS, given
    ``value_and_grad(list of float32 arrays) -> (value, list of gradients)``, from ``start``
    (default zero); returns the minimising arrays (float64)."""
    def unflat(v):
        return [np.asarray(a, np.float32) for a in unflat_vector(v, shapes)]

    def f(v):
        val, g = value_and_grad(unflat(v))
        return float(val), np.concatenate([np.asarray(gi, np.float64).ravel() for gi in g])

    v0 = (np.zeros(sum(int(np.prod(sh)) for sh in shapes)) if start is None
          else np.concatenate([np.ravel(a) for a in start]).astype(np.float64))
    res = optimize.minimize(f, v0, jac=True, method="L-BFGS-B", options={"maxiter": iters})
    return [np.asarray(a, np.float64) for a in unflat(res.x)]


def _layer_mean(ds, W, b, a, noise, physics, t, arch, layer, axis, kinds):
    """Layer ``layer``'s mean prediction with the offsets ``ds``: its model fed ``a`` (the
    measured layer before; layer 1: x through the input noise), averaged over the draws."""
    Wd, bd, ph = apply_layer(kinds, ds, W, b, physics, layer, arch)
    a_in = noisy_input(a, noise, ph) if layer == 1 else a
    return jnp.mean(layer_step(Wd, bd, a_in, noise, ph, arch, layer, t=t)[0], axis=axis)


@functools.partial(jax.jit, static_argnames=("arch", "layer", "axis", "kinds"))
def _layer_vg(ds, W, b, a, noise, physics, t, target, inv_v, inv_e2, arch, layer, axis, kinds):
    def loss(ds):
        pred = _layer_mean(ds, W, b, a, noise, physics, t, arch, layer, axis, kinds)
        prior = sum(ie * jnp.sum(d ** 2) for ie, d in zip(inv_e2, ds))
        return 0.5 * jnp.sum((target - pred) ** 2) * inv_v + 0.5 * prior
    return jax.value_and_grad(loss)(ds)


def _layer_sites(meas: Measurement, physics, layer: int, K: int, q: int):
    """The draw sites layer ``layer``'s step reads (:func:`~._shots._step_sites`, traced on
    shapes alone), for inputs of K shots (layer 1) or r shots of q draws each; None: every site."""
    arch, f32 = meas.arch, jnp.float32
    W = jax.ShapeDtypeStruct((arch.widths[layer], arch.widths[layer - 1]), f32)
    b = jax.ShapeDtypeStruct((arch.widths[layer],), f32)
    shots = K if layer == 1 else meas.r
    a = jax.ShapeDtypeStruct((meas.n, shots, arch.widths[layer - 1]), f32)
    t = None if meas.t is None else jax.ShapeDtypeStruct((meas.n, shots), f32)
    return _step_sites(W, b, a, physics, t, arch, layer, 0 if layer == 1 else q)


def _layer_setup(key, meas: Measurement, physics, layer: int, draws_per_shot: int = 4):
    """Inputs, draws, times and targets of layer ``layer``'s offset fit (taps). Only the sites the
    layer reads are drawn (each site's draws are its own: the same numbers as drawing them all)."""
    arch, n, r = meas.arch, meas.n, meas.r
    if layer == 1:
        K = 256  # the model's mean response must be much sharper than the measured mean (r shots)
        noise = compiled_draws(key, physics, arch=arch, shape=(n, K), dtype=jnp.float32,
                               sites=_layer_sites(meas, physics, 1, K, 0))
        a = to32(np.asarray(meas.x)[:, None, :])
        t = tiled_times(meas, K)
        Y = meas.layers()[0]
        target = to32(np.mean(Y, axis=1))  # (n, d1)
        resid_var = float(np.mean(np.var(Y, axis=1))) / r
        axis = 1
    else:
        noise = compiled_draws(key, physics, arch=arch, shape=(n, r, draws_per_shot), dtype=jnp.float32,
                               sites=_layer_sites(meas, physics, layer, r, draws_per_shot))
        a = to32(np.asarray(meas.taps[layer - 2])[:, :, None, :])
        t = None if meas.t is None else to32(np.broadcast_to(np.asarray(meas.t)[:, :, None], (n, r, draws_per_shot)))
        Y = meas.layers()[layer - 1]
        target = to32(Y)  # (n, r, d_l)
        resid_var = float(np.mean(np.var(Y, axis=1)))
        axis = 2
    return noise, a, t, target, resid_var, axis


@functools.partial(jax.jit, static_argnames=("arch", "layer", "axis", "kinds"))
def _layer_jvps(ds, W, b, a, noise, physics, t, basis, arch, layer, axis, kinds):
    """Layer ``layer``'s mean prediction at the offsets ``ds`` (samples..., d_l) and its change
    along each direction of ``basis`` (a tuple, per kind, of (B, shape) arrays): (B, samples...,
    d_l). The Levenberg-Marquardt fit and the effective degrees of freedom both read a
    neuron's Jacobian off these columns."""
    def pred(ds):
        return _layer_mean(ds, W, b, a, noise, physics, t, arch, layer, axis, kinds)

    p0, lin = jax.linearize(pred, ds)
    return p0, jax.vmap(lin)(basis)


def _kind_basis(ds):
    """Per kind, a direction moving that kind's value of every neuron at once (the columns of
    each neuron's Jacobian when a neuron's values move that neuron only)."""
    P = len(ds)
    return tuple(np.eye(P, dtype=np.float32)[:, i, None] * np.ones_like(np.asarray(d, np.float32))[None]
                 for i, d in enumerate(ds))


def _neuron_lm(linearised, ds, target, inv_v: float, inv_e2, iters: int = 50, atol: float = 1e-4, rtol: float = 1e-7):
    """Per-neuron values (a few per neuron: every kind at a layer of that form) by
    Levenberg-Marquardt on all neurons at once: the loss separates over neurons, each a problem
    in its own few values, so each takes its own damped Gauss-Newton steps; a step that does
    not lower a neuron's loss is refused and that neuron's damping raised. A neuron is done when
    its undamped step would lower its loss -- half a chi-square, in units of the measured
    variance -- by less than ``atol`` (its values then within ~0.014 standard errors of the
    optimum) or ``rtol`` of it (float32 predictions resolve no finer); all done, or ``iters``
    steps, ends the fit.

    ``linearised(ds) -> (mean prediction, its derivative per kind)`` as :func:`_layer_jvps` along
    :func:`_kind_basis`.
    Returns float64 arrays, one per kind."""
    d = np.stack([np.asarray(x, np.float64) for x in ds])  # (P, d_l)
    P, n_l = d.shape
    lam = np.asarray(inv_e2, np.float64)[:, None]  # (P, 1) prior precisions
    tg = np.asarray(target, np.float64).reshape(-1, n_l)
    eye = np.eye(P)[None]

    def evaluate(d):
        release_freed_memory()  # what the steps before freed (their Jacobians, solves), before this one is made
        p0, cols = linearised(tuple(np.asarray(x, np.float32) for x in d))
        r = tg - np.asarray(p0, np.float64).reshape(-1, n_l)
        loss = 0.5 * inv_v * np.sum(r * r, axis=0) + 0.5 * np.sum(lam * d * d, axis=0)
        return loss, r, np.asarray(cols, np.float64).reshape(P, -1, n_l)

    loss, r, J = evaluate(d)
    mu = np.full(n_l, 1e-3)
    for _ in range(iters):
        H = inv_v * np.einsum("psi,qsi->ipq", J, J) + eye * lam.T[:, :, None]  # (d_l, P, P)
        g = -inv_v * np.einsum("psi,si->ip", J, r) + (lam * d).T  # (d_l, P)
        # what the undamped step would gain on the quadratic model: 0.5 g^T H^-1 g
        gain = 0.5 * np.einsum("ip,ip->i", g, np.linalg.solve(H, g[:, :, None])[:, :, 0])
        if np.all(gain <= np.maximum(atol, rtol * np.abs(loss))):
            break
        Hd = H + mu[:, None, None] * eye * np.diagonal(H, axis1=1, axis2=2)[:, :, None]
        step = -np.linalg.solve(Hd, g[:, :, None])[:, :, 0].T  # (P, d_l)
        new_loss, new_r, new_J = evaluate(d + step)
        better = new_loss < loss
        d = np.where(better[None], d + step, d)
        loss, r = np.where(better, new_loss, loss), np.where(better[None], new_r, r)
        J = np.where(better[None, None], new_J, J)
        mu = np.where(better, mu / 3.0, mu * 4.0)
    return list(d)


def _layer_offsets(key, meas: Measurement, physics, p32, kinds, layer: int, scales, start=None):
    """The offsets of every kind at ``layer`` from the measured layer before (taps): by
    :func:`_neuron_lm` when every kind there has one value per neuron (biases, per-neuron
    parameters), else by L-BFGS."""
    arch = meas.arch
    here = tuple(k for k in kinds if layer in k.layers)
    if not here:
        return []
    W, b = p32[layer - 1]
    noise, a, t, target, resid_var, axis = _layer_setup(jax.random.fold_in(key, layer), meas, physics, layer)
    inv_v = jnp.float32(1.0 / max(resid_var, 1e-12))
    inv_e2 = tuple(jnp.float32(1.0 / max(scales[k], 1e-6) ** 2) for k in here)
    if all(k.target != "W" for k in here):
        d0 = [np.zeros(k.shape(arch, layer)) for k in here] if start is None else start
        basis = _kind_basis(d0)
        return _neuron_lm(lambda ds: _layer_jvps(ds, W, b, a, noise, physics, t, basis, arch, layer, axis, here), d0,
                          target, float(inv_v), [float(x) for x in inv_e2])

    def vg(ds):
        return _layer_vg(tuple(ds), W, b, a, noise, physics, t, target, inv_v, inv_e2, arch, layer, axis, here)

    return _lbfgs(vg, [k.shape(arch, layer) for k in here], start=start)


@functools.partial(jax.jit, static_argnames=("arch", "ids", "kinds"))
def _joint_vg(ds, p32, x, noise, physics, t, targets, inv_v, inv_e2, arch, ids, kinds):
    def loss(ds):
        deltas = _split_by_kind(ds, kinds)
        out = _forward_with(deltas, kinds, p32, x, noise, physics, t, arch)
        chi2 = sum(jnp.sum((tg - jnp.mean(out[l - 1], axis=1)) ** 2) * iv for tg, iv, l in zip(targets, inv_v, ids))
        prior = sum(ie * sum(jnp.sum(d ** 2) for d in deltas[k]) for ie, k in zip(inv_e2, kinds))
        return 0.5 * chi2 + 0.5 * prior
    return jax.value_and_grad(loss)(ds)


def _forward_with(deltas, kinds, p32, x, noise, physics, t, arch):
    """Every layer's output with the offsets ``deltas`` ({kind: per-layer arrays})."""
    a = noisy_input(x[:, None, :], noise, physics)
    outs = []
    for l, (W, b) in enumerate(p32, start=1):
        ds = [deltas[k][k.layers.index(l)] if l in k.layers else None for k in kinds]
        Wd, bd, ph = apply_layer(kinds, ds, W, b, physics, l, arch)
        a = layer_step(Wd, bd, a, noise, ph, arch, l, t=t)[0]
        outs.append(a)
    return outs


def _joint_setup(key, meas: Measurement, physics):
    K = max(meas.r, 32)
    noise = compiled_draws(key, physics, arch=meas.arch, shape=(meas.n, K), dtype=jnp.float32)
    t = tiled_times(meas, K)
    targets = tuple(jnp.asarray(np.mean(Y, axis=1), jnp.float32) for Y in meas.layers())
    inv_v = tuple(jnp.float32(1.0 / max(float(np.mean(np.var(Y, axis=1))) / meas.r, 1e-12)) for Y in meas.layers())
    return K, noise, t, targets, inv_v


def _joint_offsets(key, meas: Measurement, physics, p32, kinds, scales, start=None):
    """Every offset at once from the measured means (no taps: the outputs only)."""
    arch = meas.arch
    _, noise, t, targets, inv_v = _joint_setup(key, meas, physics)
    inv_e2 = tuple(jnp.float32(1.0 / max(scales[k], 1e-6) ** 2) for k in kinds)
    x = to32(meas.x)

    def vg(ds):
        return _joint_vg(tuple(ds), p32, x, noise, physics, t, targets, inv_v, inv_e2, arch, tuple(meas.layer_ids()),
                         kinds)

    shapes = [k.shape(arch, l) for k in kinds for l in k.layers]
    flat_start = None if start is None else [a for k in kinds for a in start[k]]
    return _split_by_kind(_lbfgs(vg, shapes, start=flat_start), kinds)


def estimate_offsets(key, meas: Measurement, physics, params, kinds, scales, start=None) -> dict:
    """``{kind: [offset array per layer in scope]}``: per layer from the taps when the file has
    them, else jointly from the output means (``start``: arrays to start L-BFGS from)."""
    p32 = params32(params)
    if meas.has_taps:
        out = {k: [] for k in kinds}
        for l in range(1, meas.arch.depth + 1):
            here = tuple(k for k in kinds if l in k.layers)
            st = None if start is None else [start[k][k.layers.index(l)] for k in here]
            for k, d in zip(here, _layer_offsets(key, meas, physics, p32, kinds, l, scales, start=st)):
                out[k].append(d)
        return out
    return _joint_offsets(key, meas, physics, p32, kinds, scales, start=start)


def identified_start(meas: Measurement, params, physics, kinds):
    """With taps and weight offsets: the offsets where the layer-wise identification puts them
    (:func:`~gift_theory.lab.identification.identify`: ``W_eff - W``, ``b_eff - b``; per-neuron
    parameters at 0), ``{kind: [array per layer]}`` -- a start from which L-BFGS has only the
    prior's shrinkage left to do, so weight errors as large as W itself are fitted and the
    noise level is not inflated to absorb a misfit mean -- and the noise level the
    identification reads off the shots with that map (pooled over the layers' neurons).
    ``(None, None)`` otherwise (the fit starts at 0)."""
    if not meas.has_taps or not any(k.target == "W" for k in kinds):
        return None, None
    from .identification import identify

    s = physics.params().get("s")
    ident = identify(meas, s=None if s is None else float(np.ravel(np.asarray(s))[0])).by_layer()
    widths = [meas.arch.widths[l] for l in sorted(ident)]
    level = float(np.sqrt(np.sum([w * ident[l].s ** 2 for w, l in zip(widths, sorted(ident))]) / np.sum(widths)))
    out = {}
    for k in kinds:
        arrs = []
        for l in k.layers:
            W, b = (np.asarray(v, np.float64) for v in params[l - 1])
            if k.target == "W":
                arrs.append(ident[l].W_eff - W)
            elif k.target == "b":
                arrs.append(ident[l].b_eff - b)
            else:
                arrs.append(np.zeros(k.shape(meas.arch, l)))
        out[k] = arrs
    return out, level


def fit_offsets(key, meas: Measurement, model: Model, names) -> Model:
    """``model`` with the effects ``names`` fitted as offsets: a prior N(0, e^2) per kind, e set
    from the first pass's rms and the offsets refitted once (two passes)."""
    arch = meas.arch
    kinds = kinds_of(names, arch)
    physics = reset(model.physics, kinds)
    params = model.weights(meas)
    scales = {k: _initial_scale(k, params, physics) for k in kinds}
    start, level = identified_start(meas, params, physics, kinds)
    if level is not None and np.isfinite(level) and level > 0 and "s" in physics.params():
        # the mean response the offsets are fitted to is shaped by the noise level (E tanh(z + n)
        # is compressed by n): at the identified level, not the start's -- a baseline fitted
        # with the map wrong absorbs the misfit into s (0.27 against the chip's 0.05 on heater
        # crosstalk that scrambles W; the offsets fitted there failed the held-out test at
        # p = 1e-202, at the identified level they pass)
        physics = physics.replace(s=level)
    if start is not None:  # the scale of the offsets the data show, not a fifth of W's
        scales = {k: max(float(np.sqrt(np.mean(np.concatenate([np.ravel(d) ** 2 for d in start[k]])))),
                         1e-4 * _initial_scale(k, params, physics)) for k in kinds}
    for _ in range(2):
        deltas = estimate_offsets(named_subkey(key, "offsets"), meas, physics, params, kinds, scales, start=start)
        scales = {k: max(float(np.sqrt(np.mean(np.concatenate([np.ravel(d) ** 2 for d in deltas[k]])))),
                         1e-4 * _initial_scale(k, params, physics)) for k in kinds}
        start = deltas if start is not None else None
    new_params, new_physics = apply_all(kinds, deltas, params, physics, arch)
    offsets = dict(model.offsets)
    for k in kinds:
        offsets[k.effect] = scales[k] if k.effect not in offsets else max(offsets[k.effect], scales[k])
    return Model(new_physics, new_params, offsets)


def offset_deltas(model: Model, base: Model, meas: Measurement, kinds) -> dict:
    """The fitted offsets of ``model`` relative to ``base`` (:func:`base_model`)."""
    p1, p0 = model.weights(meas), base.weights(meas)
    out = {}
    for k in kinds:
        arrs = []
        for l in k.layers:
            if k.target == "W":
                arrs.append(np.asarray(p1[l - 1].W, np.float64) - np.asarray(p0[l - 1].W, np.float64))
            elif k.target == "b":
                arrs.append(np.asarray(p1[l - 1].b, np.float64) - np.asarray(p0[l - 1].b, np.float64))
            else:
                v1 = getattr(model.physics.get(k.effect), k.target)
                v0 = getattr(base.physics.get(k.effect), k.target)
                g = lambda v: np.broadcast_to(np.asarray(v[l - 1] if isinstance(v, (tuple, list)) else v, np.float64),
                                              (meas.arch.widths[l],))
                arrs.append(g(v1) - g(v0))
        out[k] = arrs
    return out
