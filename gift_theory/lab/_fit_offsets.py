"""Stage 5b of the lab: per-device values fitted as fixed offsets, and the null that allows for them.

A model cannot know a device's fixed draws -- the weight errors E of ``weight_error``, the bias
offsets delta of ``bias_offset``, the values of a per-neuron parameter of a plugin effect
(``shape = {"p": "neurons"}``). They are estimated as fixed offsets with a Gaussian prior
(ridge; the scale re-estimated once from the first pass) through the core's differentiable
layer map -- by L-BFGS, or, on a layer (taps) whose offsets are all one value per neuron, by
a Levenberg-Marquardt step per neuron (:func:`_neuron_lm`: a few steps instead of some 30
gradient evaluations):

* with taps, layer by layer: each layer's measured output shot by shot against the model's
  mean response to the *measured* output of the layer before (layer 1: means over shots
  against the mean response to x);
* without taps, every layer at once from the output means.

What this many-parameter model costs, and whether the data identify it, is measured by its
**effective degrees of freedom**, the trace of the ridge's hat matrix
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

import concurrent.futures
import contextvars
import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize, stats

from .._measurement import Measurement
from .._model import (
    compiled_draws,
    forward,
    layer_step,
    named_subkey,
    noisy_input,
    simulate,
)
from .._params import Layer
from ..effects import REGISTRY
from ._shots import Model, params32, tiled_times

#: replicates of the refit null (see :func:`offset_replicates`)
OFFSET_REPLICATES = 8


@dataclasses.dataclass(frozen=True)
class Kind:
    """One family of fitted offsets: of effect ``effect``, added to ``target`` -- ``"W"`` (the
    weights), ``"b"`` (the biases) or the name of a per-neuron parameter of the effect -- on
    ``layers`` (1-based)."""

    effect: str
    target: str
    layers: tuple

    def shape(self, arch, layer: int) -> tuple:
        return (arch.widths[layer], arch.widths[layer - 1]) if self.target == "W" else (arch.widths[layer],)


def _in_scope(cls, layer: int, depth: int) -> bool:
    scope = getattr(cls, "layers", "all")
    if scope == "all":
        return True
    if scope == "hidden":
        return layer < depth
    if scope == "output":
        return layer == depth
    return layer in tuple(scope)


def kinds_of(names, arch) -> tuple:
    """The offset families of the effects ``names`` (built-in offsets and per-neuron parameters)."""
    out = []
    for name in names:
        cls = REGISTRY[name]
        layers = tuple(l for l in range(1, arch.depth + 1) if _in_scope(cls, l, arch.depth))
        if getattr(cls, "offsets_of", None):
            out.append(Kind(name, cls.offsets_of, layers))
        for p, kind in getattr(cls, "shape", {}).items():
            if kind == "neurons":
                out.append(Kind(name, p, layers))
    return tuple(out)


def fitted_as_offsets(name: str) -> bool:
    cls = REGISTRY[name]
    return bool(getattr(cls, "offsets_of", None)) or any(v == "neurons" for v in getattr(cls, "shape", {}).values())


# ---- applying offsets ------------------------------------------------------------------------

def _neuron_values(physics, kind: Kind, layer: int, d, arch):
    """``physics`` with the per-neuron parameter of ``kind`` at ``layer`` set to its base value + d."""
    eff = physics.get(kind.effect)
    base = getattr(eff, kind.target)
    vals = []
    for l in range(1, arch.depth + 1):
        b_l = base[l - 1] if isinstance(base, (tuple, list)) else base
        v = jnp.broadcast_to(jnp.asarray(b_l, jnp.float32), (arch.widths[l],))
        vals.append(v + d if l == layer else v)
    return physics.replace(**{kind.target: tuple(vals)})


def apply_layer(kinds, ds, W, b, physics, layer: int, arch):
    """Layer ``layer``'s (W, b, physics) with the offsets ``ds`` (one array per kind in scope)."""
    for kind, d in zip(kinds, ds):
        if d is None:
            continue
        if kind.target == "W":
            W = W + d
        elif kind.target == "b":
            b = b + d
        else:
            physics = _neuron_values(physics, kind, layer, d, arch)
    return W, b, physics


def apply_all(kinds, deltas, params, physics, arch):
    """Every layer's weights and the physics with the offsets ``deltas`` ({kind: [array per layer
    in scope]}) -- float64 weights, per-neuron parameters as tuples of per-layer arrays."""
    new = []
    for l, (W, b) in enumerate(params, start=1):
        W, b = np.asarray(W, np.float64), np.asarray(b, np.float64)
        for kind in kinds:
            if l in kind.layers and kind.target in ("W", "b"):
                d = np.asarray(deltas[kind][kind.layers.index(l)], np.float64)
                W, b = (W + d, b) if kind.target == "W" else (W, b + d)
        new.append(Layer(W, b))
    for kind in kinds:
        if kind.target in ("W", "b"):
            continue
        eff = physics.get(kind.effect)
        base = getattr(eff, kind.target)
        vals = []
        for l in range(1, arch.depth + 1):
            b_l = base[l - 1] if isinstance(base, (tuple, list)) else base
            v = np.broadcast_to(np.asarray(b_l, np.float64), (arch.widths[l],)).copy()
            if l in kind.layers:
                v = v + np.asarray(deltas[kind][kind.layers.index(l)], np.float64)
            vals.append(jnp.asarray(v, jnp.float32))
        physics = physics.replace(**{kind.target: tuple(vals)})
    return tuple(new), physics


# ---- the fit -----------------------------------------------------------------------------------

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


def unflat_vector(v, shapes):
    """A flat vector (numpy or traced) cut into arrays of ``shapes``, in order."""
    out, i = [], 0
    for sh in shapes:
        k = int(np.prod(sh))
        out.append(v[i:i + k].reshape(sh))
        i += k
    return out


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


def _layer_setup(key, meas: Measurement, physics, layer: int, draws_per_shot: int = 4):
    """Inputs, draws, times and targets of layer ``layer``'s offset fit (taps)."""
    arch, n, r = meas.arch, meas.n, meas.r
    if layer == 1:
        K = 256  # the model's mean response must be much sharper than the measured mean (r shots)
        noise = compiled_draws(key, physics, arch=arch, shape=(n, K), dtype=jnp.float32)
        a = jnp.asarray(meas.x, jnp.float32)[:, None, :]
        t = tiled_times(meas, K)
        Y = meas.layers()[0]
        target = jnp.asarray(np.mean(Y, axis=1), jnp.float32)  # (n, d1)
        resid_var = float(np.mean(np.var(Y, axis=1))) / r
        axis = 1
    else:
        noise = compiled_draws(key, physics, arch=arch, shape=(n, r, draws_per_shot), dtype=jnp.float32)
        a = jnp.asarray(meas.taps[layer - 2], jnp.float32)[:, :, None, :]
        t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)[:, :, None] * jnp.ones((1, 1, draws_per_shot))
        Y = meas.layers()[layer - 1]
        target = jnp.asarray(Y, jnp.float32)  # (n, r, d_l)
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


def _split_by_kind(ds, kinds):
    out, i = {}, 0
    for k in kinds:
        out[k] = list(ds[i:i + len(k.layers)])
        i += len(k.layers)
    return out


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
    x = jnp.asarray(meas.x, jnp.float32)

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


def _initial_scale(kind: Kind, params, physics) -> float:
    if kind.target == "W":
        return 0.2 * float(np.sqrt(np.mean(np.concatenate([np.ravel(W) ** 2 for W, _ in params]))))
    if kind.target == "b":
        return 0.05 + 0.2 * float(np.sqrt(np.mean(np.concatenate([np.ravel(b) ** 2 for _, b in params]))))
    base = np.asarray(getattr(REGISTRY[kind.effect], "defaults", {}).get(kind.target, 1.0), np.float64)
    return 0.1 * max(float(np.sqrt(np.mean(base ** 2))), 0.1)


def reset(physics, kinds):
    """``physics`` with the per-neuron parameters of ``kinds`` at their defaults (the effect added
    where missing): the point every offset of those kinds is measured from."""
    for k in kinds:
        if k.target in ("W", "b"):
            continue
        default = float(REGISTRY[k.effect].defaults.get(k.target, 0.0))
        physics = (physics.replace(**{k.target: default}) if k.effect in physics
                   else physics.with_effect(k.effect, **{k.target: default}))
    return physics


def base_model(model: Model, meas: Measurement) -> Model:
    """What a model's offsets are measured from: the programmed weights, per-neuron parameters at
    their defaults, everything else of ``model``'s physics."""
    kinds = kinds_of(list(model.offsets), meas.arch)
    return Model(reset(model.physics, kinds))


def identified_start(meas: Measurement, params, physics, kinds):
    """With taps and weight offsets: the offsets where the layer-wise identification puts them
    (:func:`~gift_theory.lab._identify.identify`: ``W_eff - W``, ``b_eff - b``; per-neuron
    parameters at 0), ``{kind: [array per layer]}`` -- a start from which L-BFGS has only the
    prior's shrinkage left to do, so weight errors as large as W itself are fitted and the
    noise level is not inflated to absorb a misfit mean. None otherwise (the fit starts at 0)."""
    if not meas.has_taps or not any(k.target == "W" for k in kinds):
        return None
    from ._identify import identify

    s = physics.params().get("s")
    ident = identify(meas, s=None if s is None else float(np.ravel(np.asarray(s))[0])).by_layer()
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
    return out


def fit_offsets(key, meas: Measurement, model: Model, names) -> Model:
    """``model`` with the effects ``names`` fitted as offsets: a prior N(0, e^2) per kind, e set
    from the first pass's rms and the offsets refitted once (two passes)."""
    arch = meas.arch
    kinds = kinds_of(names, arch)
    physics = reset(model.physics, kinds)
    params = model.weights(meas)
    scales = {k: _initial_scale(k, params, physics) for k in kinds}
    start = identified_start(meas, params, physics, kinds)
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


# ---- effective degrees of freedom -------------------------------------------------------------

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
        d_l, d_in = arch.widths[l], arch.widths[l - 1]
        # columns per neuron: each W kind contributes d_in (entry j of every row), b / per-neuron 1
        dirs = []
        for ki, k in enumerate(here):
            cols = d_in if k.target == "W" else 1
            for j in range(cols):
                v = [np.zeros(kk.shape(arch, l), np.float32) for kk in here]
                if k.target == "W":
                    v[ki][:, j] = 1.0
                else:
                    v[ki][:] = 1.0
                dirs.append((v, e[k]))
        basis = tuple(np.stack([d[0][i] for d in dirs]) for i in range(len(here)))
        zero = tuple(np.zeros(k.shape(arch, l), np.float32) for k in here)
        cols = np.asarray(_layer_jvps(zero, W, b, a, noise, model.physics, t, basis, arch, l, axis, here)[1],
                          np.float64)
        cols = cols.reshape(len(dirs), -1, d_l)  # (P_i, samples, neurons)
        prior = np.array([d[1] ** 2 for d in dirs])
        # per neuron i, J_i (samples, P_i) scaled by the prior and the noise; the eigenvalues of
        # J_i^T J_i (a P_i x P_i Gram matrix per neuron: the squared singular values of J_i)
        Js = np.ascontiguousarray(np.transpose(cols * (np.sqrt(prior) / np.sqrt(resid_var))[:, None, None], (2, 1, 0)))
        lam = np.clip(np.linalg.eigvalsh(np.swapaxes(Js, 1, 2) @ Js), 0.0, None)
        total += float(np.sum(lam / (lam + 1.0)))
    return total, nominal


def _output_jacobian(key, meas: Measurement, model: Model, kinds, chunk: int = 64):
    """J (n d_L, P) of the model's mean outputs in every offset, and the inverse variance of a
    measured mean (no taps)."""
    arch = meas.arch
    K, noise, t, _, _ = _joint_setup(named_subkey(key, "jacobian"), meas, model.physics)
    x = jnp.asarray(meas.x, jnp.float32)
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


# ---- the refit null -------------------------------------------------------------------------

def resimulate(key, model: Model, meas: Measurement) -> Measurement:
    """``meas`` with its shots (and taps) replaced by shots of ``model`` taken as the truth:
    same inputs, shots per input, times and programmed weights."""
    t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)
    out = simulate(key, params32(model.weights(meas)), jnp.asarray(meas.x, jnp.float32), model.physics, meas.arch,
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
    base_out = _mean_output(params32(base.weights(meas)), jnp.asarray(meas.x, jnp.float32), noise, base.physics, t, arch)
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
            z = spread @ np.asarray(jax.random.normal(k_truth, (spread.shape[1],)), np.float64)
            flat = np.concatenate([np.ravel(a) for k in kinds for a in fitted[k]]) + z
            deltas = _split_by_kind(unflat_vector(flat, shapes), kinds)
            p, ph = apply_all(kinds, deltas, base.weights(fit_meas), base.physics, arch)
            truth = Model(ph, p, model.offsets)
        sim_tr = resimulate(k_tr, truth, fit_meas)
        deltas = estimate_offsets(k_fit, sim_tr, base.physics, base.weights(fit_meas), kinds, scales, start=fitted)
        p, ph = apply_all(kinds, deltas, base.weights(fit_meas), base.physics, arch)
        refit = Model(ph, p, model.offsets)
        return channel_values(k_cmp, refit, resimulate(k_te, truth, test_meas), ref, shots)

    # the replicates are independent (each from its own subkey): ``workers`` threads make them at once
    if workers > 1 and B > 1:
        with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
            out = [f.result() for f in [pool.submit(contextvars.copy_context().run, replicate, b) for b in range(B)]]
    else:
        out = [replicate(b) for b in range(B)]
    return np.stack(out)


# ---- is the fitted model its own effect? --------------------------------------------------------

#: a normal-theory test refuses the fitted values beyond this |z| (a structure the prior excludes)
PRIOR_Z = 4.0
#: the coupling test (an exact randomisation p-value) refuses below this, Bonferroni over its layers
PRIOR_P = 0.01
#: Haar rotations drawn per layer by the coupling test (layers up to :data:`COUPLING_MC_WIDTH` outputs)
COUPLING_DRAWS = 20000
COUPLING_MC_WIDTH = 64
#: ... stopping early once this many exceed the observed statistic (Besag & Clifford 1991)
COUPLING_STOP = 20


def coupling_test(E: np.ndarray, W: np.ndarray, seed=0) -> tuple[float, float]:
    """Are the rows of the fitted offsets E coupled the way the rows of W are? ``(z, p)``.

    Under weight_error's prior the rows of E (one per output neuron) are independent draws of
    one law, whatever the programmed W: E's law is unchanged by any rotation O E of its rows
    (exactly for Gaussian rows N(0, V), any V). A coupling between the inputs, E = W M (dense
    crosstalk), gives rows whose Gram matrix E E^T follows W W^T. The statistic
    T = tr(A O M O^T), A = W W^T, M = E E^T, at O = I is referred to its law under Haar
    rotations O of the rows given E^T E -- an exact conditional test. In the eigenbases,
    T = sum_kj lam_k mu_j O_kj^2 over the r = rank(M) non-zero mu, so only r columns of each
    rotation are drawn (orthonormalised Gaussians): :data:`COUPLING_DRAWS` of them up to
    :data:`COUPLING_MC_WIDTH` rows (p with the +1 correction), stopped once
    :data:`COUPLING_STOP` exceed T (then p = that count over the draws: a valid sequential
    p-value, Besag & Clifford 1991, so a layer far from significance costs ~1000); beyond that a normal law with
    T's exact rotation mean tr(A) tr(M) / d and variance 2 tr(A~^2) tr(M~^2) / ((d - 1)(d + 2))
    (A~, M~ without their trace parts). One-sided: only a Gram aligned with W's is a coupling.
    ``seed``: the rotations' random numbers."""
    A, M = W @ W.T, E @ E.T
    d = A.shape[0]
    t0 = float(np.sum(A * M))
    if d <= COUPLING_MC_WIDTH:
        lam = np.linalg.eigvalsh(A)
        mu, _ = np.linalg.eigh(M)
        mu = mu[mu > 1e-12 * max(mu.max(), 1e-300)]
        rng = np.random.default_rng(seed)
        exceed, done = 0, 0
        while done < COUPLING_DRAWS:
            Q, _ = np.linalg.qr(rng.standard_normal((min(1000, COUPLING_DRAWS - done), d, mu.size)))
            t = np.einsum("k,bkj,j->b", lam, Q * Q, mu)
            exceed, done = exceed + int(np.sum(t >= t0 * (1 - 1e-12))), done + len(t)
            if exceed >= COUPLING_STOP:  # Besag & Clifford's sequential p-value: h / draws
                return float(stats.norm.isf(exceed / done)), float(exceed / done)
        p = (1 + exceed) / (1 + done)
        return float(stats.norm.isf(p)), float(p)
    At, Mt = A - np.trace(A) / d * np.eye(d), M - np.trace(M) / d * np.eye(d)
    mean = np.trace(A) * np.trace(M) / d
    sd = np.sqrt(2.0 * np.sum(At * At) * np.sum(Mt * Mt) / ((d - 1) * (d + 2)))
    z = float((t0 - mean) / sd) if sd > 0 else 0.0
    return z, float(stats.norm.sf(z))


def outlier_test(d: np.ndarray) -> tuple[int, float, float]:
    """Is one of the offsets ``d`` a gross outlier of N(0, e^2) draws, e unknown? Grubbs' test:
    G = max |d_i - mean| / sd, referred to its exact Student-t bound (P times the two-sided tail
    of t = sqrt(P (P - 2) G^2 / ((P - 1)^2 - P G^2)) on P - 2 degrees of freedom; exact for
    the largest value of P normal draws, conservative otherwise). ``(index, z, p)``."""
    d = np.ravel(np.asarray(d, np.float64))
    P = d.size
    sd = np.std(d, ddof=1) if P >= 3 else 0.0
    if P < 3 or sd <= 0:
        return 0, 0.0, 1.0
    i = int(np.argmax(np.abs(d - d.mean())))
    G = abs(d[i] - d.mean()) / sd
    den = (P - 1) ** 2 - P * G * G
    t = np.sqrt(P * (P - 2) * G * G / den) if den > 0 else np.inf
    p = float(min(1.0, P * 2.0 * stats.t.sf(t, P - 2))) if np.isfinite(t) else 0.0
    return i, float(stats.norm.isf(max(p / 2.0, 1e-300))) if p < 1.0 else 0.0, p


def refusing(rows) -> list[dict]:
    """The rows of :func:`prior_check` that refuse the fitted values: a normal-theory z beyond
    :data:`PRIOR_Z`, a coupling p below :data:`PRIOR_P` over the number of layers tested."""
    rows = list(rows or ())
    n_p = sum(1 for r in rows if "p" in r)
    return [r for r in rows if (r["p"] < PRIOR_P / n_p if "p" in r else abs(r["z"]) > PRIOR_Z)]


def prior_check(model: Model, meas: Measurement, seed: int = 0) -> list[dict]:
    """Do the fitted offsets look like their effect's prior -- E iid N(0, e^2) drawn
    independently of the programmed W (``weight_error``), delta iid N(0, sigma^2)
    (``bias_offset``)? Tests per layer, each a z (:func:`refusing` says which refuse):

    ``b_mean``         the mean of a layer's fitted bias offsets over their spread (Student t
                       on the normal scale): offsets all one way are a shifted transfer (an
                       activation's asymmetry seen through the biases), not draws of either sign;

    ``w_correlation``  atanh of the correlation of E_hat with W, times sqrt(P - 3): offsets
                       proportional to W are a gain (an activation slope seen through the
                       weights), not an error drawn apart from them;
    ``w_structure``    where the layer has more rows than columns (d_out >= d_in + 3), the F
                       test of E_hat = W M (each row of the error a fixed linear map of the row
                       of W: a coupling between the inputs, dense crosstalk): the share of
                       E_hat in the column space of W against d_in / d_out under the prior;
    ``w_coupling``     on every layer of two or more outputs, :func:`coupling_test`: the rows
                       of E_hat coupled as the rows of W are (a coupling W M on a layer of any
                       shape); its row also carries the exact p-value ``p``.

    ``{target}_outlier`` per layer and per-neuron family of five or more offsets (biases,
                       per-neuron parameters), :func:`outlier_test`: one
                       gross outlier (a 5-sigma offset among N(0, e^2) draws) is not a draw of
                       the prior; its row names the value (``neuron``, ``value``) and carries
                       the p-value ``p`` and a sentence ``what``.

    ``seed``: the coupling test's rotations (layer l draws with ``(seed, l)``).
    Returns one row per layer with offsets: ``{layer, test, z}`` for each test that applies.
    """
    all_kinds = kinds_of(list(model.offsets), meas.arch)
    deltas_of = offset_deltas(model, base_model(model, meas), meas, all_kinds)
    out = []
    for kind in (k for k in all_kinds if k.target == "b"):
        # bias_offset's prior is symmetric: offsets all one way are a shifted transfer, not a draw
        for l, d in zip(kind.layers, deltas_of[kind]):
            if d.size >= 3 and np.std(d, ddof=1) > 0:
                t = float(np.mean(d) / (np.std(d, ddof=1) / np.sqrt(d.size)))
                p = 2.0 * stats.t.sf(abs(t), df=d.size - 1)
                out.append({"layer": int(l), "test": "b_mean",
                            "z": float(np.sign(t) * stats.norm.isf(max(p / 2.0, 1e-300)))})
    # one gross outlier among the offsets (a dead or stuck neuron, a broken weight) is not a draw
    # of N(0, e^2): Grubbs' test per layer and family, the value named
    for kind in all_kinds:
        for l, d in zip(kind.layers, deltas_of[kind]):
            # per-neuron families only: a weight error's fitted entries are shrunk unevenly (most
            # directions set by the prior without taps), far from a sample of one normal law
            if kind.target == "W" or d.size < 5:
                continue
            i, z, p = outlier_test(d)
            where = f"{l}:{i}"
            out.append({"layer": int(l), "test": f"{kind.target}_outlier", "z": z, "p": p,
                        "neuron": where, "value": float(np.ravel(d)[i]),
                        "what": f"{kind.effect} offsets of layer {{l}} single out {where}: "
                                f"{float(np.ravel(d)[i]):+.3g} against the others' rms "
                                f"{float(np.sqrt(np.mean(np.delete(np.ravel(d), i) ** 2))):.3g} (not a draw of "
                                f"N(0, e^2): that one is unlike the rest, e.g. a dead or stuck neuron)"})
    kinds = [k for k in all_kinds if k.target == "W"]
    if not kinds:
        return out
    for l, E in zip(kinds[0].layers, deltas_of[kinds[0]]):
        W = np.asarray(meas.params[l - 1].W, np.float64)
        P = E.size
        if P > 3 and np.std(E) > 0 and np.std(W) > 0:
            rho = float(np.corrcoef(E.ravel(), W.ravel())[0, 1])
            out.append({"layer": int(l), "test": "w_correlation",
                        "z": float(np.arctanh(np.clip(rho, -0.999999, 0.999999)) * np.sqrt(P - 3))})
        d_out, d_in = W.shape
        if d_out >= d_in + 3 and np.linalg.matrix_rank(W) == d_in:
            proj = W @ np.linalg.pinv(W) @ E
            ss_p, ss_r = float(np.sum(proj ** 2)), float(np.sum((E - proj) ** 2))
            df1, df2 = d_in * d_in, (d_out - d_in) * d_in
            F = (ss_p / df1) / max(ss_r / df2, 1e-300)
            z = float(stats.norm.isf(max(stats.f.sf(F, df1, df2), 1e-300)))
            out.append({"layer": int(l), "test": "w_structure", "z": z})
        if d_out >= 2 and np.std(E) > 0:
            z, p = coupling_test(E, W, seed=(seed, int(l)))
            out.append({"layer": int(l), "test": "w_coupling", "z": z, "p": p})
    return out
