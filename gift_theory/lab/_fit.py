"""Fit a model's physical parameters to measurements.

One method for every effect: *simulated moment matching with common random numbers*.
The model's shots for the fitting inputs are a deterministic function of the physics
parameters once the standard draws are fixed (the core's explicit-noise forward pass), so
the per-cell moments of the model -- mean and log variance per neuron, log variance of
the layer sum (cross-neuron correlation: common mode), slope against acquisition time
(drift) -- are smooth in the parameters except through the rounding of quantization. The
loss is the sum of the standardised squared moment differences over every measured cell
(taps and output). It is minimised by a one-dimensional grid over each new parameter
followed by Nelder-Mead on all of them (no gradient needed, so quantization's rounding is
no obstacle). Two effects need more than moments:

* quantization: the lattice spacing is read off the measured values (they sit on the
  multiples of ``step``); ``bits`` is the smallest integer with ``step 2^(bits-1)`` at least
  the largest measured magnitude, ``v_range = step 2^(bits-1)``.
* weight_error: a model cannot know the device's E, so it is fitted as fixed offsets
  ``E_hat`` (prior N(0, e^2), e re-estimated once, L-BFGS through the differentiable layer
  map): with taps layer by layer, each layer's measured output shot by shot against the
  model's mean response to the measured output of the layer before (layer 1: means over
  shots against the mean response to x); without taps all layers at once from the output
  means. The fitted model uses ``W + E_hat`` and reports ``e``. Held-out inputs judge
  whether the offsets generalise; its p-value is taken against a refit null that allows
  for their estimation error (:func:`offset_replicates`).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .._errors import GiftInputError
from .._model import forward, layer_step, sample_noise
from .._params import Layer
from ..effects import REGISTRY, Physics, make_effect
from ._compare import Model, _times, draws, layer_outputs, params32
from ._measurement import Measurement

#: candidate effects a diagnosis can add (awgn is the baseline)
CANDIDATES = ("laplace", "uniform", "multiplicative", "common_mode", "drift", "crosstalk",
              "weight_error", "shot", "saturation", "quantization")

#: grids for the one-dimensional scan of each new parameter: (kind, values)
_GRIDS = {
    "s": ("log", np.geomspace(1e-4, 3.0, 25)),
    "m": ("log", np.geomspace(1e-3, 1.0, 13)),
    "c": ("log", np.geomspace(1e-3, 1.0, 13)),
    "q": ("log", np.geomspace(1e-5, 1.0, 16)),
    "r": ("lin", np.linspace(-0.6, 0.6, 25)),
    "k": ("lin", np.linspace(-0.3, 0.3, 25)),
    "v_max": ("log", None),  # set from the data's magnitude
}

#: number of free parameters each candidate adds (for the parsimony penalty)
N_PARAMS = {"laplace": 0, "uniform": 0, "multiplicative": 1, "common_mode": 1, "drift": 1, "crosstalk": 1,
            "weight_error": 3, "shot": 1, "saturation": 1, "quantization": 2, "awgn": 1}


def split_inputs(key, n: int, frac: float = 0.5):
    """Random disjoint (fit, held-out) index arrays over ``n`` inputs."""
    if n < 4:
        raise GiftInputError(f"measurement has {n} inputs; fitting and held-out scoring need at least 4")
    perm = np.asarray(jax.random.permutation(key, n))
    k = n - int(round(n * (1 - frac)))  # held-out half n // 2 (equal halves share compiled shapes)
    k = min(max(k, 2), n - 2)
    return np.sort(perm[:k]), np.sort(perm[k:])


# ---- moments ---------------------------------------------------------------------------

def _moments(A, t):
    """Per-cell moments of shots A (n, K, d) with times t (n, K) or None."""
    K = A.shape[1]
    m = jnp.mean(A, 1)
    v = jnp.var(A, 1) * K / (K - 1)
    sv = jnp.var(jnp.sum(A, -1), 1) * K / (K - 1)
    out = {"m": m, "v": v, "sv": sv}
    if t is not None:
        tc = t - jnp.mean(t, 1, keepdims=True)
        vt = jnp.mean(tc ** 2, 1)
        out["beta"] = jnp.einsum("nk,nkd->nd", tc, A - m[:, None, :]) / K / jnp.maximum(vt, 1e-12)[:, None]
        out["vt"] = vt
    return out


def _moment_loss(mod, dat, r, K):
    """Mean standardised squared difference of the moments (one layer)."""
    vfloor = 1e-6 * jnp.mean(dat["v"]) + 1e-20
    lv = jnp.log(mod["v"] + vfloor) - jnp.log(dat["v"] + vfloor)
    lsv = jnp.log(mod["sv"] + vfloor) - jnp.log(dat["sv"] + vfloor)
    var_lv = 2.0 / (r - 1) + 2.0 / (K - 1)
    terms = [jnp.mean((mod["m"] - dat["m"]) ** 2 / (dat["v"] / r + mod["v"] / K + vfloor)),
             jnp.mean(lv ** 2) / var_lv, jnp.mean(lsv ** 2) / var_lv]
    if "beta" in dat:
        vt = jnp.maximum(dat["vt"], 1e-12)[:, None]
        se2 = (dat["v"] / r + mod["v"] / K) / vt + vfloor
        # cells whose shots span no time carry no slope information
        w = (dat["vt"] > 1e-10)[:, None]
        terms.append(jnp.sum(w * (mod["beta"] - dat["beta"]) ** 2 / se2) / jnp.maximum(jnp.sum(w) * dat["m"].shape[1], 1))
    return sum(terms)


def data_moments(meas: Measurement):
    t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)
    return tuple(_moments(jnp.asarray(Y, jnp.float32), t) for Y in meas.layers())


# ---- quantization lattice --------------------------------------------------------------

def lattice_step(meas: Measurement):
    """The spacing of the lattice the measured values sit on, or None if they do not.

    The candidate step is the smallest clear gap between distinct measured values; the
    values are on the lattice when every one is within 1e-4 step of a multiple of it.
    """
    vals = np.concatenate([np.ravel(a) for a in meas.layers()])
    u = np.unique(np.round(vals, 9))
    if len(u) > 0.5 * len(vals) or len(u) < 2:
        return None
    gaps = np.diff(u)
    scale = max(np.max(np.abs(u)), 1e-12)
    gaps = gaps[gaps > 1e-7 * scale]
    if len(gaps) == 0:
        return None
    step = float(np.min(gaps))
    # refine with the median of gaps that are one step wide
    one = gaps[np.abs(gaps / step - 1.0) < 0.01]
    step = float(np.median(one)) if len(one) else step
    resid = np.abs(u / step - np.round(u / step))
    if np.max(resid) > 1e-3:
        return None
    return step


def quantization_from_lattice(meas: Measurement):
    """``(bits, v_range)`` read off the measured lattice, or None."""
    step = lattice_step(meas)
    if step is None:
        return None
    vmax = max(float(np.max(np.abs(a))) for a in meas.layers())
    bits = max(1, int(np.ceil(np.log2(max(vmax / step, 1.0) - 1e-6))) + 1)
    bits = min(bits, 32)
    return float(bits), float(step * 2.0 ** (bits - 1))


# ---- the fit ---------------------------------------------------------------------------

def _transforms_static(physics, free, theta):
    vals = {}
    for i, p in enumerate(free):
        eff = next(e for e in physics.effects if p in e.params)
        lo, _ = type(eff).bounds.get(p, (-np.inf, np.inf))
        vals[p] = jnp.exp(theta[i]) if lo >= 0 else theta[i]
    return vals


class _Problem:
    """The fitting data of one measurement, shared by every candidate model."""

    def __init__(self, key, meas: Measurement, K: int | None = None):
        self.meas = meas
        self.key = key
        self.arch = meas.arch
        self.K = 2 * meas.r if K is None else int(K)
        self.x = jnp.asarray(meas.x, jnp.float32)
        self.t = None
        if meas.t is not None:
            reps = -(-self.K // meas.r)
            self.t = jnp.asarray(np.tile(meas.t, (1, reps))[:, :self.K], jnp.float32)
        self.dat = data_moments(meas) if self.K == meas.r else None
        if self.dat is None:
            t = self.t[:, :meas.r] if self.t is not None else None
            self.dat = tuple(_moments(jnp.asarray(Y, jnp.float32), t) for Y in meas.layers())
        ids = meas.layer_ids()
        # forward returns every layer; only measured ones enter the loss
        self.dat_full = tuple(self.dat[ids.index(l)] if l in ids else None for l in range(1, self.arch.depth + 1))

    def loss(self, physics, params, free):
        """``theta -> moment loss`` for the free parameters (common random numbers)."""
        noise = draws(self.key, physics, self.arch, (self.meas.n, self.K))
        dat = self.dat_full
        p32 = params32(params)
        r, K, t = self.meas.r, self.K, self.t

        def f(theta):
            phys = physics.replace(**_transforms_static(physics, tuple(free), jnp.asarray(theta, jnp.float32)))
            outs = layer_outputs(p32, self.x, noise, phys, self.arch, t)
            return _loss_of_outputs(outs, dat, t, (r, K))
        return f


@functools.partial(jax.jit, static_argnames=("rK",))
def _loss_of_outputs(outs, dat, t, rK):
    r, K = rK
    total = 0.0
    for A, d in zip(outs, dat):
        if d is not None:
            total = total + _moment_loss(_moments(A, t), d, r, K)
    return total


def _optimise(f, theta0, grids):
    """Grid scan over each coordinate listed in ``grids`` (index -> theta values), then
    Nelder-Mead on all coordinates."""
    theta = np.array(theta0, dtype=np.float64)
    for i, values in grids.items():
        best, bv = None, np.inf
        for v in values:
            th = theta.copy()
            th[i] = v
            val = float(f(th))
            if np.isfinite(val) and val < bv:
                best, bv = v, val
        if best is not None:
            theta[i] = best
    res = optimize.minimize(lambda th: float(f(th)), theta, method="Nelder-Mead",
                            options={"xatol": 1e-3, "fatol": 1e-4, "maxiter": 80 * len(theta),
                                     "initial_simplex": _simplex(theta)})
    th = res.x if res.fun <= float(f(theta)) else theta
    return th, float(f(th))


def _simplex(theta, step=0.25):
    pts = [theta.copy()]
    for i in range(len(theta)):
        p = theta.copy()
        p[i] += step if abs(theta[i]) < 1 else step * abs(theta[i])
        pts.append(p)
    return np.array(pts)


def _theta_of(physics, free):
    th = []
    for p in free:
        eff = next(e for e in physics.effects if p in e.params)
        lo, _ = type(eff).bounds.get(p, (-np.inf, np.inf))
        v = float(eff.param_dict()[p])
        th.append(np.log(max(v, 1e-12)) if lo >= 0 else v)
    return np.array(th)


def _grid_theta(name, physics, meas):
    kind, values = _GRIDS[name]
    if name == "v_max":
        vmax = max(float(np.max(np.abs(a))) for a in meas.layers())
        values = np.geomspace(0.3 * vmax, 30 * vmax, 17)
    return np.log(values) if kind == "log" else values


def _lbfgs(value_and_grad, shapes, iters: int = 300, start=None):
    """Minimise a function of a list of arrays of ``shapes`` by L-BFGS, given
    ``value_and_grad(list of float32 arrays) -> (value, list of gradients)``, from ``start``
    (default zero); returns the minimising arrays (float64)."""
    def unflat(v):
        return [jnp.asarray(a, jnp.float32) for a in _unflat(v, shapes)]

    def f(v):
        val, g = value_and_grad(unflat(v))
        return float(val), np.concatenate([np.asarray(gi, np.float64).ravel() for gi in g])

    v0 = np.zeros(sum(int(np.prod(sh)) for sh in shapes)) if start is None else np.concatenate([np.ravel(a) for a in start]).astype(np.float64)
    res = optimize.minimize(f, v0, jac=True, method="L-BFGS-B", options={"maxiter": iters})
    return [np.asarray(a, np.float64) for a in unflat(res.x)]


# module-level jitted losses: compiled once per shape and physics structure, not per call
@functools.partial(jax.jit, static_argnames=("arch", "layer", "axis"))
def _layer_vg(ds, W, b, a, noise, physics, t, target, inv_v, inv_e2, arch, layer, axis):
    def loss(ds):
        (dW,) = ds
        pred = jnp.mean(layer_step(W + dW, b, a, noise, physics, arch, layer, t=t)[0], axis=axis)
        return 0.5 * jnp.sum((target - pred) ** 2) * inv_v + 0.5 * inv_e2 * jnp.sum(dW ** 2)
    return jax.value_and_grad(loss)(ds)


@functools.partial(jax.jit, static_argnames=("arch", "ids"))
def _joint_vg(ds, p32, x, noise, physics, t, targets, inv_v, inv_e2, arch, ids):
    def loss(ds):
        ps = tuple(Layer(W + dW, b) for (W, b), dW in zip(p32, ds))
        out = forward(ps, x[:, None, :], noise, physics, arch, t=t, taps=True)
        chi2 = sum(jnp.sum((tg - jnp.mean(out.taps[l - 1], axis=1)) ** 2) * iv for tg, iv, l in zip(targets, inv_v, ids))
        return 0.5 * chi2 + 0.5 * inv_e2 * sum(jnp.sum(dW ** 2) for dW in ds)
    return jax.value_and_grad(loss)(ds)


def _layer_offsets(problem: _Problem, physics: Physics, p32, layer: int, e: float, draws_per_shot: int = 8,
                   start=None):
    """E_hat of one layer from the measured layer before (taps): the layer's output shot by
    shot against the model's mean response to the *measured* input of that shot (layer 1:
    mean over shots against the mean response to x)."""
    meas, arch = problem.meas, problem.arch
    n, r = meas.n, meas.r
    W, b = p32[layer - 1]
    key = jax.random.fold_in(problem.key, 31 + layer)
    if layer == 1:
        K = 256  # the model's mean response must be much sharper than the measured mean (r shots)
        noise = sample_noise(key, arch, physics, (n, K), jnp.float32)
        a = problem.x[:, None, :] + (physics.s * noise["a0"] if "a0" in noise else 0.0)
        t = None if problem.t is None else problem.t[:, :K]
        target = jnp.asarray(np.mean(meas.layers()[0], axis=1), jnp.float32)  # (n, d1)
        resid_var = float(np.mean(np.var(meas.layers()[0], axis=1))) / r
        axis = 1
    else:
        noise = sample_noise(key, arch, physics, (n, r, draws_per_shot), jnp.float32)
        a = jnp.asarray(meas.taps[layer - 2], jnp.float32)[:, :, None, :]
        t = None if problem.t is None else problem.t[:, :r, None] * jnp.ones((1, 1, draws_per_shot))
        target = jnp.asarray(meas.layers()[layer - 1], jnp.float32)  # (n, r, d_l)
        resid_var = float(np.mean(np.var(meas.layers()[layer - 1], axis=1)))
        axis = 2
    inv_e2 = jnp.float32(1.0 / max(e, 1e-6) ** 2)
    inv_v = jnp.float32(1.0 / max(resid_var, 1e-12))

    def vg(ds):
        return _layer_vg(ds, W, b, a, noise, physics, t, target, inv_v, inv_e2, arch, layer, axis)

    (dW,) = _lbfgs(vg, [W.shape], start=None if start is None else [start])
    return dW


def _joint_offsets(problem: _Problem, physics: Physics, p32, e: float, start=None):
    """E_hat of every layer at once from the measured means (no taps: the outputs only)."""
    meas, arch = problem.meas, problem.arch
    K = max(meas.r, 32)
    noise = sample_noise(jax.random.fold_in(problem.key, 17), arch, physics, (meas.n, K), jnp.float32)
    t = None if problem.t is None else problem.t[:, :K]
    targets = tuple(jnp.asarray(np.mean(Y, axis=1), jnp.float32) for Y in meas.layers())
    inv_v = tuple(jnp.float32(1.0 / max(float(np.mean(np.var(Y, axis=1))) / meas.r, 1e-12)) for Y in meas.layers())
    inv_e2 = jnp.float32(1.0 / max(e, 1e-6) ** 2)

    def vg(ds):
        return _joint_vg(ds, p32, problem.x, noise, physics, t, targets, inv_v, inv_e2, arch, tuple(meas.layer_ids()))

    return _lbfgs(vg, [W.shape for W, _ in p32], start=start)


def _fit_weight_offsets(problem: _Problem, physics: Physics, params):
    """Offsets E_hat (a fixed per-device error cannot be a random effect of a model): per layer
    from the taps when the file has them (each layer's output regressed, shot by shot, on the
    measured output of the layer before), else jointly from the output means; ridge prior
    N(0, e^2) with e re-estimated once from the first pass."""
    p32 = params32(params)
    rms_w = float(np.sqrt(np.mean(np.concatenate([np.ravel(W) ** 2 for W, _ in params]))))
    e = 0.2 * rms_w
    for _ in range(2):
        deltas = _offsets(problem, physics, p32, e)
        e = max(float(np.sqrt(np.mean(np.concatenate([np.ravel(d) ** 2 for d in deltas])))), 1e-4 * rms_w)
    return _with_offsets(params, deltas), e


def _offsets(problem: _Problem, physics: Physics, p32, e: float, start=None):
    """Offsets of every layer: per layer from the taps when the file has them, else jointly
    from the output means (``start``: one array per layer to start L-BFGS from)."""
    if problem.meas.has_taps:
        return [_layer_offsets(problem, physics, p32, l, e, start=None if start is None else start[l - 1])
                for l in range(1, problem.arch.depth + 1)]
    return _joint_offsets(problem, physics, p32, e, start=start)


def _with_offsets(params, deltas):
    """``W + delta`` per layer, float64."""
    return tuple(Layer(np.asarray(W, np.float64) + d, np.asarray(b, np.float64)) for (W, b), d in zip(params, deltas))


def _resimulate(key, model: Model, meas: Measurement) -> Measurement:
    """``meas`` with its shots (and taps) replaced by shots of ``model`` taken as the truth:
    same inputs, shots per input, times and programmed weights."""
    from .._model import simulate

    p32 = params32(model.params if model.params is not None else meas.params)
    t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)
    out = simulate(key, p32, jnp.asarray(meas.x, jnp.float32), model.physics, meas.arch, shots=meas.r, t=t,
                   taps=True)
    taps = tuple(np.asarray(a, np.float64) for a in out.taps[:-1]) if meas.has_taps else None
    return dataclasses.replace(meas, y=np.asarray(out.y, np.float64), taps=taps)


#: replicates of the refit null of a model with fitted offsets (see :func:`offset_replicates`)
OFFSET_REPLICATES = 8


def offset_replicates(key, model: Model, fit_meas: Measurement, test_meas: Measurement, ref, *,
                      shots: int | None = None, B: int = OFFSET_REPLICATES, K: int | None = None) -> np.ndarray:
    """Channel values of a model with fitted weight offsets under the null *with* its
    estimation error, for :func:`compare`'s ``null_replicates``: B times, data are simulated
    from the fitted model as the truth on the fitting inputs, the offsets refitted (the same
    estimator, with the model's prior scale e, from the fitted values), and the refitted
    model scored on data simulated on the held-out inputs.

    A few hundred offsets fitted on a few thousand noisy means leave an estimation error
    that held-out data see (about one squared standard error per offset); without this a
    correct weight_error model fails its own held-out test whenever weights are many for
    the inputs (docs/lab.md).

    Returns
    -------
    (B, n_test, L', C) array
    """
    from ._compare import channel_values

    if model.params is None or "weight_error" not in model.extra:
        raise ValueError("offset_replicates: the model has no fitted offsets")
    e = float(model.extra["weight_error"])
    E_hat = [np.asarray(W1, np.float64) - np.asarray(W0, np.float64)
             for (W1, _), (W0, _) in zip(model.params, fit_meas.params)]
    # with taps every layer's offsets are identified and the fitted model can stand for the
    # truth; without taps most directions are not, and the truth of each replicate is drawn
    # from the offsets' posterior (the part of E the data cannot see, at its full size)
    spread = None if fit_meas.has_taps else _posterior_spread(jax.random.fold_in(key, 977), model, fit_meas, e)
    out = []
    for b in range(B):
        kb = jax.random.fold_in(key, b)
        k_tr, k_te, k_fit, k_cmp = jax.random.split(kb, 4)
        truth = model
        if spread is not None:
            z = spread @ np.asarray(jax.random.normal(jax.random.fold_in(kb, 5), (spread.shape[1],)), np.float64)
            truth = Model(model.physics, _with_offsets(model.params, _unflat(z, [a.shape for a in E_hat])),
                          model.extra)
        sim_tr = _resimulate(k_tr, truth, fit_meas)
        deltas = _offsets(_Problem(k_fit, sim_tr, K), model.physics, params32(fit_meas.params), e, start=E_hat)
        refit = Model(model.physics, _with_offsets(fit_meas.params, deltas), model.extra)
        out.append(channel_values(k_cmp, refit, _resimulate(k_te, truth, test_meas), ref, shots))
    return np.stack(out)


def _unflat(v, shapes):
    """A flat vector (numpy or traced) cut into arrays of ``shapes``, in order."""
    out, i = [], 0
    for sh in shapes:
        k = int(np.prod(sh))
        out.append(v[i:i + k].reshape(sh))
        i += k
    return out


def _marginal_e2(d2, c2, sigma2: float) -> float:
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
    # e^2 d_k^2 beyond the whole residual in every direction is past the maximum
    top = np.log(float(np.sum(c2)) + sigma2) - np.log(float(np.min(d2[d2 > 0])))
    res = optimize.minimize_scalar(nll, bounds=(top - 60.0, top), method="bounded")
    return float(np.exp(res.x))


def _posterior_spread(key, model: Model, meas: Measurement, e_fit: float, K: int = 32, chunk: int = 64):
    """A square root S of the offsets' posterior covariance from the output means (no taps),
    linearised at the fit: with J the Jacobian of the model's mean outputs in the offsets and
    v the inverse variance of a measured mean, ``S S^T = (v J^T J + I / e^2)^-1``.

    e is the empirical-Bayes scale (:func:`_marginal_e2` on r0, the residual of the programmed
    weights' mean outputs; the model's K-draw mean adds r/K to the measured means' variance),
    not the fitted one: the ridge estimate sets the unidentified directions to zero, so the
    rms of E_hat underestimates e (0.09 for a true 0.15 on 8-16-8-4). Never below the
    fitted e."""
    arch, r = meas.arch, meas.r
    p_hat, p_0 = params32(model.params), params32(meas.params)
    noise = sample_noise(key, arch, model.physics, (meas.n, K), jnp.float32)
    t = _times(meas, K)  # tiled when K exceeds the shots per input
    x = jnp.asarray(meas.x, jnp.float32)
    Y = meas.layers()[-1]
    target = np.mean(Y, axis=1).ravel()
    v = r / max(float(np.mean(np.var(Y, axis=1))), 1e-12)  # inverse variance of a mean, as the fit weighs them
    shapes = [W.shape for W, _ in p_hat]
    P = sum(int(np.prod(sh)) for sh in shapes)
    cols = []
    for i in range(0, P, chunk):
        basis = np.zeros((min(chunk, P - i), P), np.float32)
        basis[np.arange(basis.shape[0]), i + np.arange(basis.shape[0])] = 1.0
        cols.append(np.asarray(_mean_output_jvp(p_hat, x, noise, model.physics, t, jnp.asarray(basis), arch,
                                                tuple(shapes)), np.float64))
    J = np.concatenate(cols, axis=0).T  # (n d_L, P)
    r0 = target - np.asarray(_mean_output(p_0, x, noise, model.physics, t, arch), np.float64).ravel()
    U, d, _ = np.linalg.svd(np.sqrt(v) * J, full_matrices=False)
    e2 = max(_marginal_e2(d ** 2, (U.T @ (np.sqrt(v) * r0)) ** 2, 1.0 + r / K), e_fit ** 2)
    # the eigenbasis of the precision (not the SVD's right basis, which would draw the
    # replicates' truths differently from the calibrated runs of docs/lab.md)
    lam, W = np.linalg.eigh(v * (J.T @ J) + np.eye(P) / e2)
    return W * (1.0 / np.sqrt(np.maximum(lam, 1e-300)))[None, :]


def _mean_out(p32, x, noise, physics, t, arch):
    return jnp.mean(forward(p32, x[:, None, :], noise, physics, arch, t=t).y, axis=1)


_mean_output = jax.jit(_mean_out, static_argnames=("arch",))


@functools.partial(jax.jit, static_argnames=("arch", "shapes"))
def _mean_output_jvp(p32, x, noise, physics, t, basis, arch, shapes):
    """Directional derivatives of the mean outputs (n, d_L), flattened, along each row of
    ``basis`` (offsets of every weight matrix, flattened in layer order)."""
    def f(flat):
        ps = tuple(Layer(W + d, b) for (W, b), d in zip(p32, _unflat(flat, shapes)))
        return _mean_out(ps, x, noise, physics, t, arch).ravel()

    zero = jnp.zeros(basis.shape[1], jnp.float32)
    return jax.vmap(lambda v: jax.jvp(f, (zero,), (v,))[1])(basis)


def fit_model(key, meas: Measurement, effects=(), *, start: Model | None = None, K: int | None = None) -> Model:
    """Fit awgn's ``s`` and the parameters of ``effects`` (names of CONTRACTS §2) to ``meas``.

    Parameters
    ----------
    key : PRNG key (the common random numbers of the fit)
    meas : Measurement (the fitting inputs)
    effects : effect names to include besides awgn (and those of ``start``)
    start : a model whose physics and values start the fit (default: awgn only)
    K : model shots per input of the fit (default 2 r)

    Returns
    -------
    Model with fitted parameters
    """
    problem = _Problem(key, meas, K)
    physics = start.physics if start is not None else Physics.create(s=0.1)
    params = meas.params if start is None or start.params is None else start.params
    extra = dict(start.extra) if start is not None else {}
    new = [e for e in effects if e not in physics.names and not (e == "weight_error" and "weight_error" in extra)]
    for name in new:
        if name not in REGISTRY:
            raise GiftInputError(f"--add: unknown effect {name!r}; known: {', '.join(REGISTRY)}")
        if name == "awgn":
            continue
        if name in ("laplace", "uniform") and physics.law != "gaussian":
            raise GiftInputError(f"--add {name}: the model already has the noise law {physics.law}")
    grid_params = ["s"] if start is None else []
    if "weight_error" in new:
        params, e = _fit_weight_offsets(problem, physics, params)
        extra["weight_error"] = e
    for name in new:
        if name in ("awgn", "weight_error"):
            continue
        if name == "quantization":
            q = quantization_from_lattice(meas)
            bits, v_range = q if q is not None else (16.0, max(float(np.max(np.abs(a))) for a in meas.layers()))
            physics = physics.with_effect(make_effect("quantization", bits=bits, v_range=v_range))
            continue
        if name == "drift" and meas.t is None:
            raise GiftInputError("--add drift: the measurement has no acquisition times t, drift is silent without them")
        eff = make_effect(name)
        physics = physics.with_effect(eff)
        grid_params += list(eff.params)
    free = tuple(p for p in physics.params() if p not in ("bits", "v_range"))
    f = problem.loss(physics, params, free)
    theta0 = _theta_of(physics, free)
    grids = {free.index(p): _grid_theta(p, physics, meas) for p in grid_params if p in free}
    if start is not None and new and "s" in free:
        # an added effect usually takes over part of the variance s had absorbed: scan s
        # down from its old value once more after the new parameter's scan
        i = free.index("s")
        th_s = np.log(max(float(physics.s), 1e-12)) + np.log([0.4, 0.55, 0.7, 0.85, 1.0, 1.1])
        grids = {**grids, i: th_s} if i not in grids else grids
        grids = {**{k: v for k, v in grids.items() if k != i}, i: th_s}
    theta, _ = _optimise(f, theta0, grids)
    vals = {p: float(v) for p, v in zip(free, [np.exp(th) if lo >= 0 else th for th, lo in
                                                  zip(theta, [_lower(physics, p) for p in free])])}
    physics = physics.replace(**vals)
    return Model(physics, None if params is meas.params else params, extra)


def _lower(physics, p):
    eff = next(e for e in physics.effects if p in e.params)
    return type(eff).bounds.get(p, (-np.inf, np.inf))[0]
