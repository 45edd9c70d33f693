"""Estimators of grad_w J_s, d/ds grad_w J_s, d^2/ds^2 grad_w J_s, d/dtheta grad_w J and Hess_w J_s v.

Paper Section "Calculation of (d/ds) grad J" (eqs. sample_D0_Wi, sample_D0_bi,
d-ds-nablaW-ENO, d ds nablab ENO). Every estimator averages over the hierarchical K1 x K2
design (K1 inputs, K2 noise draws each) and returns an :class:`~gift_theory.Estimate` whose
``mean`` and ``se`` are pytrees shaped like the weights.

Methods for d/ds grad_w J_s
---------------------------
``score_paper``
    D^[0] exactly as printed: mean of  [sum_alpha (s^-2 |N^alpha|^2 - d_alpha)] R^(l) A^(l-1)^T.
    Since grad_W (y - M)^2 = -2 R A^T (eqn:backpropagation-for-W), this is one backward
    pass of the score-weighted loss times -1/2.  The derivation, redone, gives
    d/ds grad J = E[(1/s) sum_alpha (|N^alpha|^2/s^2 - d_alpha) grad_w (y-M)^2]: the printed
    lemma lem:chain-derivative drops a factor 1/s, and eq. d-ds-nablab-ENO drops backprop's
    -2, so  E[D^[0]] = -(s/2) d/ds grad J  (see :func:`paper_constant`).
``score``
    The score-function estimator with the derived constants, and a leave-one-out control
    variate: the score of draw m is centred on the mean score of the input's other K2 - 1
    draws' gradients, which reduces to weights K2/(K2-1) (c_m - mean_m c_m) (unbiased because
    the baseline is independent of draw m). Gaussian and Laplace noise laws.
``pathwise``
    The additive noise is s * xi with standard xi: d/ds of grad_w (y - M)^2 by
    forward-over-reverse autodiff (``jax.jvp`` of ``jax.grad``) at fixed xi.
``fd``
    Central finite differences in s of grad_w at fixed xi (common random numbers), step
    ``h`` (default 1e-2 s).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from .._arch import Architecture
from .. import _xla
from .._errors import GiftInputError, require
from .._model import compiled_draws, forward, squared_error
from ..effects import Physics
from ..effects.awgn import additive_sites
from ._hierarchical import hierarchical_mean

D_DS_METHODS = ("score_paper", "score", "pathwise", "fd")
D2_DS2_METHODS = ("score", "pathwise", "fd")
D_DTHETA_METHODS = ("pathwise", "fd", "score")


def paper_constant(s: float) -> float:
    """The factor c with E[D^[0]_printed] = c * d/ds grad J_s: c = -s/2."""
    return -0.5 * float(s)


# ----------------------------------------------------------------------------- kernels
def _weighted_loss(params, physics, arch, x, y, noise, cw):
    """sum_{i,m} cw_im (y_i - M(x_i, w, N_im))^2 for x (m, d0), noise (m, K2, .), cw (m, K2)."""
    m, K2 = cw.shape
    flat = {k: v.reshape((m * K2,) + v.shape[2:]) for k, v in noise.items()}
    out = forward(params, jnp.repeat(x, K2, axis=0), flat, physics, arch).y
    return jnp.sum(cw.reshape(-1) * squared_error(out, jnp.repeat(y, K2, axis=0)))


def _score_stats(noise, arch, physics):
    """Per draw: Q = sum over additive sites of the score statistic, D = total dimension.

    Gaussian: Q = sum xi^2 (score (Q - D)/s); Laplace: Q = sqrt(2) sum |xi|.
    """
    sites = [k for k in additive_sites(arch) if k in noise]
    law = physics.law
    if law == "uniform":
        raise GiftInputError("score estimators: the uniform law's support depends on s, so it has no score; "
                             "use method='pathwise' or 'fd'")
    Q = 0.0
    D = 0
    for k in sites:
        xi = noise[k]
        Q = Q + (jnp.sum(xi * xi, axis=-1) if law == "gaussian" else jnp.sqrt(2.0) * jnp.sum(jnp.abs(xi), axis=-1))
        D += xi.shape[-1]
    return Q, D


def _centre(c):
    """Leave-one-out baseline over the K2 draws of each input (last axis): K2/(K2-1) (c - mean c)."""
    K2 = c.shape[-1]
    if K2 < 2:
        return c
    return (c - jnp.mean(c, axis=-1, keepdims=True)) * (K2 / (K2 - 1))


def _grad(params, physics, arch, x, y, noise, cw):
    return jax.grad(_weighted_loss)(params, physics, arch, x, y, noise, cw)


def _set(physics, theta, value):
    return physics.replace(**{theta: value})


def _block_quantity(what, method, theta, arch, params, physics, x, y, w, noise, h, v):
    """Per-group sum of one quantity for x (m, d0), y (m, dL), w (m,), noise (m, K2, .)."""
    K2 = jax.tree_util.tree_leaves(noise)[0].shape[1]
    base = (w / K2)[:, None] * jnp.ones((1, K2), x.dtype)
    grad = partial(_grad, arch=arch, x=x, y=y, noise=noise)
    if what == "grad":
        return grad(params, physics, cw=base)
    if what == "hvp":
        return jax.jvp(lambda p: grad(p, physics, cw=base), (params,), (v,))[1]
    value = physics.params()[theta]
    s = physics.s
    if what == "d1":
        if method == "pathwise":
            return jax.jvp(lambda t: grad(params, _set(physics, theta, t), cw=base), (value,),
                           (jnp.ones_like(value),))[1]
        if method == "fd":
            gp = grad(params, _set(physics, theta, value + h), cw=base)
            gm = grad(params, _set(physics, theta, value - h), cw=base)
            return jax.tree_util.tree_map(lambda a, b: (a - b) / (2 * h), gp, gm)
        Q, D = _score_stats(noise, arch, physics)
        if method == "score_paper":
            # printed eq. sample_D0_Wi: (s0^-2 N^T N - d) R A^T with R A^T = -1/2 grad (y-M)^2
            # (the -1/2 goes into the per-sample weights, not over the per-group gradients)
            return grad(params, physics, cw=base * (Q - D) * -0.5)
        # derived: d/ds log phi_s(N) = (Q - D) / s
        return grad(params, physics, cw=base * _centre(Q - D) / s)
    if what == "d2":
        if method == "pathwise":
            def d1(t):
                return jax.jvp(lambda u: grad(params, _set(physics, theta, u), cw=base), (t,),
                               (jnp.ones_like(t),))[1]
            return jax.jvp(d1, (value,), (jnp.ones_like(value),))[1]
        if method == "fd":
            gp = grad(params, _set(physics, theta, value + h), cw=base)
            g0 = grad(params, physics, cw=base)
            gm = grad(params, _set(physics, theta, value - h), cw=base)
            return jax.tree_util.tree_map(lambda a, b, c: (a - 2 * b + c) / (h * h), gp, g0, gm)
        Q, D = _score_stats(noise, arch, physics)
        if physics.law != "gaussian":
            raise GiftInputError("d2_ds2_grad score: only the Gaussian law; use method='pathwise' or 'fd'")
        # phi''/phi = u^2 + u' with u = (Q - D)/s, u' = (D - 3Q)/s^2
        return grad(params, physics, cw=base * _centre((Q - D) ** 2 + D - 3 * Q) / (s * s))
    raise ValueError(what)


@partial(_xla.jit, static_argnames=("what", "method", "theta", "arch"))
def _kernel(xb, yb, wb, noise, params, physics, h, v, *, what, method, theta, arch):
    # one vmapped pass over the block's groups: the forward products of all groups are one
    # matmul, the per-group weight gradients one batched matmul (measured on 2 cores: as fast
    # as the ungrouped gradient for groups of >= 512 samples)
    f = partial(_block_quantity, what, method, theta, arch, params, physics, h=h, v=v)
    return jax.vmap(f)(xb, yb, wb, noise)


def _block(key, xb, yb, wb, params, physics, h, v, *, what, method, theta, arch, K2):
    dtype = jnp.dtype(params[0].W.dtype)
    noise = compiled_draws(key, physics, arch=arch, shape=tuple(xb.shape[:2]) + (K2,), dtype=dtype)
    return _kernel(xb, yb, wb, noise, params, physics, h, v, what=what, method=method, theta=theta, arch=arch)


def _run(what, method, theta, key, params, x, y, physics, arch, K2, h, v, groups, chunk, keep_samples):
    require(isinstance(physics, Physics), "estimator: physics must be a gift_theory.Physics")
    dtype = params[0].W.dtype
    x = jnp.asarray(x, dtype)
    y = jnp.asarray(y, dtype)
    require(x.ndim == 2 and x.shape[1] == arch.widths[0],
            f"estimator: x has shape {tuple(x.shape)}, architecture {arch} needs (K1, {arch.widths[0]})")
    require(y.shape == (x.shape[0], arch.widths[-1]),
            f"estimator: y has shape {tuple(y.shape)}, needs ({x.shape[0]}, {arch.widths[-1]})")
    fn = partial(_block, what=what, method=method, theta=theta, arch=arch, K2=int(K2))
    return hierarchical_mean(fn, key, x, y, K2=int(K2), groups=groups, chunk=chunk, keep_samples=keep_samples,
                             block_args=(params, physics, jnp.asarray(h, dtype), v))


def _check_theta(physics, theta):
    names = physics.params()
    require(theta in names, f"estimator: theta={theta!r} is not a parameter of {physics.describe()}; "
                            f"parameters: {', '.join(names) or 'none'}")
    return float(names[theta])


def _step(physics, theta, h):
    value = _check_theta(physics, theta)
    if h is None:
        h = 1e-2 * abs(value) if value != 0 else 1e-3
    require(h > 0, f"estimator: finite-difference step h must be positive, got {h}")
    return h


# ----------------------------------------------------------------------------- public
def grad_objective(key, params, x, y, physics: Physics, arch: Architecture, *, K2: int = 8, groups: int = 16,
                   chunk: int = 16384, keep_samples: bool = False):
    """grad_w J_s(w) on the inputs ``x`` (eq. objective-function-as-a-function-of-s).

    Parameters
    ----------
    key : PRNG key (same key, same draws)
    params : tuple of Layer
    x : (K1, d_0) inputs; y : (K1, d_L) targets
    physics, arch : the model
    K2 : noise draws per input
    groups : number of independent units for the standard error (batch means over inputs; 16
        groups give the standard error 15 degrees of freedom and keep each group's weight-gradient
        product large enough to run at full matmul speed)
    chunk : maximum number of samples (inputs x draws) per compiled block

    Returns
    -------
    Estimate with ``mean``, ``se`` shaped like ``params`` and ``n`` independent units.
    """
    return _run("grad", "pathwise", "s", key, params, x, y, physics, arch, K2, 0.0, None, groups, chunk, keep_samples)


def hvp(key, params, x, y, physics: Physics, arch: Architecture, v, *, K2: int = 8, groups: int = 16,
        chunk: int = 16384, keep_samples: bool = False):
    """Hess_w J_s(w) @ v by forward-over-reverse autodiff at fixed draws.

    ``v`` is a pytree shaped like ``params``. Same key, same draws: an HVP with a fixed key
    is a linear map of v (needed by conjugate gradients).
    """
    v = jax.tree_util.tree_map(lambda a, p: jnp.asarray(a, p.dtype), v, params)
    return _run("hvp", "pathwise", "s", key, params, x, y, physics, arch, K2, 0.0, v, groups, chunk, keep_samples)


def d_ds_grad(key, params, x, y, physics: Physics, arch: Architecture, *, method: str = "pathwise", K2: int = 8,
              h: float | None = None, groups: int = 16, chunk: int = 16384, keep_samples: bool = False):
    """An estimate of d/ds grad_w J_s(w) (paper Section "Calculation of (d/ds) grad J").

    Parameters
    ----------
    key : PRNG key (same key, same draws: methods compared on one key share their draws)
    params : tuple of Layer
    x : (K1, d_0) inputs; y : (K1, d_L) targets
    physics : Physics with ``awgn`` (s is its level)
    method : "score_paper" | "score" | "pathwise" | "fd" (see the module docstring).
        ``score_paper`` estimates ``paper_constant(s) * d/ds grad J``, i.e. -s/2 times it.
    K2 : noise draws per input; h : finite-difference step in s (fd)
    groups, chunk, keep_samples : see :func:`grad_objective`

    Returns
    -------
    Estimate (mean, se pytrees like params; n independent units).
    """
    require(method in D_DS_METHODS, f"d_ds_grad: unknown method {method!r}; known: {', '.join(D_DS_METHODS)}")
    require("awgn" in physics, "d_ds_grad: the physics has no additive noise level s (no awgn effect)")
    h = _step(physics, "s", h) if method == "fd" else 0.0
    return _run("d1", method, "s", key, params, x, y, physics, arch, K2, h, None, groups, chunk, keep_samples)


def d2_ds2_grad(key, params, x, y, physics: Physics, arch: Architecture, *, method: str = "pathwise", K2: int = 8,
                h: float | None = None, groups: int = 16, chunk: int = 16384, keep_samples: bool = False):
    """An estimate of d^2/ds^2 grad_w J_s(w): "pathwise" (forward-over-forward-over-reverse),
    "fd" (second central difference at fixed draws) or "score" (phi''/phi weights, centred)."""
    require(method in D2_DS2_METHODS, f"d2_ds2_grad: unknown method {method!r}; known: {', '.join(D2_DS2_METHODS)}")
    require("awgn" in physics, "d2_ds2_grad: the physics has no additive noise level s (no awgn effect)")
    h = _step(physics, "s", h if h is not None else 5e-2 * float(physics.s)) if method == "fd" else 0.0
    return _run("d2", method, "s", key, params, x, y, physics, arch, K2, h, None, groups, chunk, keep_samples)


def d_dtheta_grad(key, params, x, y, physics: Physics, arch: Architecture, *, theta: str = "s",
                  method: str = "pathwise", K2: int = 8, h: float | None = None, groups: int = 16,
                  chunk: int = 16384, keep_samples: bool = False):
    """An estimate of d/dtheta grad_w J for any physical parameter ``theta`` of ``physics``
    (``"s"``, ``"q"``, ``"m"``, ``"k"``, ...): "pathwise" (autodiff through the effect at
    fixed standard draws), "fd" (central difference, common draws) or, for theta = s,
    "score". Non-differentiable effects (quantization's rounding) need "fd"."""
    require(method in D_DTHETA_METHODS,
            f"d_dtheta_grad: unknown method {method!r}; known: {', '.join(D_DTHETA_METHODS)}")
    _check_theta(physics, theta)
    if method == "score":
        require(theta == "s", f"d_dtheta_grad: the score method needs theta='s', got {theta!r}")
    h = _step(physics, theta, h) if method == "fd" else 0.0
    return _run("d1", method, theta, key, params, x, y, physics, arch, K2, h, None, groups, chunk, keep_samples)
