"""The rivals of GIFT under the same chip budget: SPSA, hybrid physics-aware training (PAT),
identify-then-retrain, and the retrain oracle."""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._errors import require
from .._model import forward, named_subkey, sample_noise, squared_error
from .._params import flatten
from ..effects import Physics
from ..training import TrainConfig, train

#: warm-start retraining from w0 (oracle and identify-retrain use the same recipe)
RETRAIN = TrainConfig(method="minibatch", epochs=20, lr=0.01, momentum=0.9, batch_size=32)


def retrain(problem, physics: Physics, *, config: TrainConfig = RETRAIN, seed: int = 0):
    """Noise-aware mini-batch SGD in silico under ``physics``, starting from w0 (no chip use)."""
    key = jax.random.fold_in(problem.key, 700 + seed)
    return train(key, problem.arch, problem.x, problem.y, physics, config, params=problem.w0)


# ------------------------------------------------------------------------ identify-retrain
@partial(jax.jit, static_argnames=("arch",))
def _shot_variance(s, key, params, x, physics, arch, shots_like):
    shots = shots_like.shape[0]
    noise = sample_noise(key, arch, physics, (x.shape[0], shots), params[0].W.dtype)
    y = forward(params, x[:, None, :], noise, physics.replace(s=s), arch).y
    return jnp.mean(jnp.sum(jnp.var(y, axis=1, ddof=1), axis=-1))


def identify_noise_level(problem, *, shots: int = 8, evaluations: float = 1.0, draws: int = 4):
    """Estimate the chip's additive noise level from repeated shots at w0 (method of moments).

    The within-input variance of the outputs over ``shots`` repeats, summed over outputs and
    averaged over inputs, is matched to the model's (common random numbers, bisection in s).
    Uses ``evaluations`` units of chip budget.

    Returns
    -------
    s_hat, info (measured variance and its standard error, s_hat's delta-method se)
    """
    n = int(min(problem.K1, max(2, math.floor(evaluations * problem.unit_shots / shots))))
    m = problem.chip.measure(problem.w0, problem.x_ft[:n], shots)
    v_i = np.sum(np.var(np.asarray(m.y, np.float64), axis=1, ddof=1), axis=-1)
    V, V_se = float(v_i.mean()), float(v_i.std(ddof=1) / math.sqrt(n))
    x = jnp.asarray(problem.x_ft[:n])
    key = jax.random.fold_in(problem.key, 801)
    like = jnp.zeros((shots,))

    def model_V(s):
        return float(np.mean([_shot_variance(jnp.float32(s), jax.random.fold_in(key, d), problem.w0, x,
                                             problem.model, problem.arch, like) for d in range(draws)]))

    lo, hi = 0.0, max(problem.s0, 1e-3)
    while model_V(hi) < V and hi < 100:
        lo, hi = hi, 2 * hi
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if model_V(mid) < V:
            lo = mid
        else:
            hi = mid
    s_hat = 0.5 * (lo + hi)
    ds = 1e-3 * max(s_hat, 1e-3)
    slope = (model_V(s_hat + ds) - model_V(max(s_hat - ds, 0.0))) / (2 * ds)
    return s_hat, {"s_hat": s_hat, "s_hat_se": V_se / slope if slope > 0 else None, "variance": V,
                   "variance_se": V_se, "inputs": n, "shots": shots}


def identify_physics(problem, *, shots: int = 16, evaluations: float = 2.0, taps: bool = True, seed: int = 0):
    """Measure the chip at w0 and find its physics with the measurement lab.

    ``evaluations`` units of chip budget buy ``shots`` repeated shots of as many fine-tuning
    inputs as they pay for (with the hidden layers where the chip has taps); the lab's
    :func:`~gift_theory.lab.diagnose` fits awgn and every effect of reference §2 (but
    weight_error, whose fixed offsets retraining cannot use) on half the inputs and tests
    them on the other half. The physics is the top-ranked model when the awgn model fails
    its test (p < 0.01), else the awgn model with its fitted s.

    Returns
    -------
    physics, info (the inputs and shots used, the baseline p-value, the ranking's top three)
    """
    from ..lab import default_candidates, diagnose
    from ..lab._offset_kinds import fitted_as_offsets

    n = int(min(problem.K1, max(8, math.floor(evaluations * problem.unit_shots / shots))))
    meas = problem.chip.measure(problem.w0, problem.x_ft[:n], shots, taps=taps)
    physics, info = physics_of(named_subkey(problem.key, f"identify{seed}"), meas)
    return physics, {**info, "inputs": n, "shots": shots}


def physics_of(key, meas):
    """The physics a measurement of w0 shows, for retraining: the lab's diagnosis over every effect
    but the per-device offsets (retraining draws no device, so it cannot use them); the
    top-ranked model when the awgn model fails its test and that model passes, else the awgn
    model at its fitted level (a model the data reject is no chip to retrain under).

    Returns
    -------
    physics, info (``physics``, ``taps``, ``baseline_p``, ``missing_effect_detected``, ``ranking``
    (the top three), ``top_status``, ``used``)
    """
    from ..lab import default_candidates, diagnose
    from ..lab._offset_kinds import fitted_as_offsets

    d = diagnose(key, meas, candidates=[c for c in default_candidates(meas) if not fitted_as_offsets(c)])
    top = d.ranking[0] if d.ranking else None
    passes = top is not None and top.status == "passes"
    physics = top.model.physics if d.missing_effect_detected and passes else d.baseline.physics
    return physics, {"physics": physics.describe(), "taps": meas.has_taps,
                     "baseline_p": d.baseline_comparison.p_value,
                     "missing_effect_detected": d.missing_effect_detected,
                     "ranking": [c.as_json()["effect"] for c in d.ranking[:3]],
                     "top_status": None if top is None else top.status,
                     "used": "the top-ranked model" if d.missing_effect_detected and passes else
                     ("the awgn model (the top-ranked model fails its test)" if d.missing_effect_detected else
                      "the awgn model (it fits)")}


def identify_retrain(problem, *, confirm: bool = True, z_accept: float = 2.5, **kw):
    """Spend part of the budget measuring the chip, identify its physics (s and any missing effect
    of docs/reference.md §2 the data do not reject, :func:`identify_physics`), retrain in silico at
    the estimate from w0; then confirm the retrained weights against w0 on the chip (paired
    evaluations on fresh shots, the line search's rule) and return w0 unless the chip finds them
    significantly better. A chip with fixed per-device errors (detector gains, offsets, fixed maps)
    can be read as noise effects that retraining under makes worse on the chip; the confirmation
    is what keeps that from being returned. ``confirm=False``: the retrained weights as they are."""
    from ._linesearch import confirm_on_chip

    physics, info = identify_physics(problem, **kw)
    w = retrain(problem, physics)
    if not confirm:
        return w, info
    accepted, conf = confirm_on_chip(problem, w, z_accept=z_accept)
    info.update(conf, accepted=accepted)
    return (w if accepted else problem.w0), info


# ------------------------------------------------------------------------------- SPSA
def spsa(problem, *, batch: int = 64, c: float = 0.01, step: float = 5e-4, alpha: float = 0.602,
         gamma: float = 0.101, calibration: int = 4):
    """Simultaneous-perturbation stochastic approximation in situ (Spall's gains).

    Each iteration sends one mini-batch of the fine-tuning set through the chip at
    w + c_k Delta and w - c_k Delta (Delta Rademacher; the same inputs for both sides), and
    steps w <- w - a_k (L+ - L-) / (2 c_k) Delta. ``a`` is calibrated (Spall's practice) on
    the mean |g| of ``calibration`` gradient estimates at w0 -- charged to the budget like
    every other query -- so that the first step moves each weight by about ``step``; no step
    moves a weight by more than 10 ``step`` (one lucky tiny |g| must not blow the weights up).
    """
    vec0, unravel = flatten(problem.w0)
    vec = np.asarray(vec0, np.float64)
    per_iter = 2 * batch * problem.K2
    remaining = problem.chip.ledger.remaining()
    n_iter = int(remaining // per_iter) if math.isfinite(remaining) else 100
    rng = np.random.default_rng(int(jax.random.randint(problem.key, (), 0, 2**31 - 1)))
    A = 0.1 * max(n_iter, 1)

    def loss(v, idx):
        out = problem.chip.measure(unravel(jnp.asarray(v, jnp.float32)), problem.x_ft[idx], problem.K2).y
        return float(np.mean(np.sum((np.asarray(out, np.float64) - problem.y_ft[idx][:, None, :]) ** 2, axis=-1)))

    def estimate(v, ck):
        idx = rng.choice(problem.K1, size=min(batch, problem.K1), replace=False)
        delta = rng.choice([-1.0, 1.0], size=v.shape)
        return (loss(v + ck * delta, idx) - loss(v - ck * delta, idx)) / (2 * ck), delta

    n_cal = min(calibration, n_iter)
    g_cal = [abs(estimate(vec, c)[0]) for _ in range(n_cal)]
    n_iter -= n_cal
    scale = float(np.mean(g_cal)) if g_cal else 0.0
    a = step * (A + 1) ** alpha / max(scale, 1e-8)
    for k in range(n_iter):
        ck = c / (k + 1) ** gamma
        g, delta = estimate(vec, ck)
        move = float(np.clip(a / (k + 1 + A) ** alpha * g, -10 * step, 10 * step))
        vec = vec - move * delta
    return unravel(jnp.asarray(vec, jnp.float32)), {"iterations": n_iter, "batch": batch, "calibration": n_cal,
                                                    "gain_a": a}


# ------------------------------------------------------------------------------- PAT
@partial(jax.jit, static_argnames=("arch", "tx", "draws"))
def _pat_step(params, opt_state, key, x, y, y_chip, physics, arch, tx, draws=1):
    def loss(p):
        shape = (y_chip.shape[0], y_chip.shape[1] * draws)
        noise = sample_noise(key, arch, physics, shape, p[0].W.dtype)
        out = forward(p, x[:, None, :], noise, physics, arch).y
        if draws == 1:  # the chip's value forward, the model's derivative backward
            out = out + jax.lax.stop_gradient(y_chip - out)
        else:  # the chip's mean error forward; the model's own spread (and its derivative) kept
            out = out + jax.lax.stop_gradient(jnp.mean(y_chip, 1, keepdims=True) - jnp.mean(out, 1, keepdims=True))
        return jnp.mean(squared_error(out, y[:, None, :]))

    g = jax.grad(loss)(params)
    updates, opt_state = tx.update(g, opt_state, params)
    return optax.apply_updates(params, updates), opt_state


def pat(problem, *, batch: int = 32, lr: float = 0.01, momentum: float = 0.9, noise: str = "s0", draws: int = 8,
        start=None, level: float | None = None, reserve: float = 0.0):
    """Hybrid physics-aware training: forward passes on the chip, gradients through the model.

    Mini-batch SGD on the fine-tuning set until the chip budget is spent.

    ``noise="s0"`` (the textbook rule): each step's output is the chip's measurement, its
    derivative the model's at s0 (one model draw per shot). The gradient is then 2 (y_chip - y)
    d out/dw: it carries the chip's mean error but not the derivative of the chip's noise
    variance, the other half of the loss E|y_chip - y|^2 -- on a chip noisier than the model
    (st > s0) the steps fit the mean by growing weights that amplify the chip's noise, so the
    true loss can rise while the mean error falls (``gift demo``: 0.73 -> 0.93 at s0 = 0.05,
    st = 0.2).

    ``noise="identified"``: one evaluation first estimates the chip's additive noise level
    (:func:`identify_noise_level`), and the model at that level takes ``draws`` draws per shot;
    the step's output is the model's own draws shifted by the chip's mean error (y_chip's mean
    minus the model's), so the gradient is the chip's mean error times the model's derivative plus
    the derivative of the model's noise variance at the chip's level: the whole loss.

    ``start``: the weights to start from (default w0); ``level``: the chip's noise level when it
    is already known (no evaluation spent on it); ``reserve``: chip evaluations left unspent.
    """
    require(noise in ("s0", "identified"), f"pat: noise={noise!r}; known: s0, identified")
    tx = optax.sgd(lr, momentum=momentum)
    params = problem.w0 if start is None else start
    opt_state = tx.init(params)
    physics, info = problem.model, {}
    if noise == "identified":
        if level is None:
            s_hat, info = identify_noise_level(problem, evaluations=1.0)
        else:
            s_hat, info = level, {}
        physics = problem.model.replace(s=float(s_hat))
    per_step = batch * problem.K2
    remaining = problem.chip.ledger.remaining() - reserve * problem.unit_shots
    n_steps = int(remaining // per_step) if math.isfinite(remaining) else 100
    rng = np.random.default_rng(int(jax.random.randint(jax.random.fold_in(problem.key, 3), (), 0, 2**31 - 1)))
    key = jax.random.fold_in(problem.key, 901)
    d = 1 if noise == "s0" else int(draws)
    for k in range(n_steps):
        idx = rng.choice(problem.K1, size=min(batch, problem.K1), replace=False)
        y_chip = jnp.asarray(problem.chip.measure(params, problem.x_ft[idx], problem.K2).y, jnp.float32)
        params, opt_state = _pat_step(params, opt_state, jax.random.fold_in(key, k), jnp.asarray(problem.x_ft[idx]),
                                      jnp.asarray(problem.y_ft[idx]), y_chip, physics, problem.arch, tx, d)
    return params, {"steps": n_steps, "batch": batch, "lr": lr, "noise": noise,
                    **({"noise_level": physics.s, "noise_level_se": info.get("s_hat_se")} if noise != "s0" else {})}
