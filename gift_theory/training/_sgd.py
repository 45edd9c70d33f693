"""In-silico training of M_s at noise level s0.

* :func:`projected_sgd` -- eq. projected-sgd exactly: one sample (x, y) and one noise
  draw per step, w <- p_H(w - eps_k grad (y - M_s(x, w, N))^2), with Robbins-Monro step
  sizes eps_k = eps0 / (k0 + k)^gamma, gamma in (1/2, 1], which satisfy (A4)
  (sum eps_k = inf, sum eps_k^2 < inf).
* the paper's practical variant (Section "Simulation study"): mini-batches, no projection.
* an optax optimiser (adam by default) over the same noise-aware mini-batch loss.

All three sample fresh noise at every step (noise-aware training at s0) and run their
inner loops as ``jax.lax.scan`` under ``jit``.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from functools import partial
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._arch import Architecture
from .._errors import require
from .._model import forward, sample_noise, squared_error
from .._params import Box, init_params, project
from ..effects import Physics

METHODS = ("minibatch", "projected_sgd", "optax")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """How to train. Every field is part of the cache key.

    Parameters
    ----------
    method : "minibatch" (paper's practice), "projected_sgd" (eq. projected-sgd) or "optax"
    epochs : passes over the training set (minibatch, optax)
    batch_size : mini-batch size (minibatch, optax)
    lr : step size (minibatch: constant SGD step; optax: learning rate)
    momentum : heavy-ball momentum for minibatch (0 = plain SGD as in the paper)
    optimizer : optax optimiser name (``adam``, ``sgd``, ``adamw``)
    steps : number of single-sample steps (projected_sgd)
    eps0, k0, gamma : Robbins-Monro steps eps_k = eps0 / (k0 + k)^gamma (projected_sgd)
    box : the hyperrectangle H (projected_sgd)
    init_gain : scale of the Glorot initialisation
    """

    method: str = "minibatch"
    epochs: int = 60
    batch_size: int = 32
    lr: float = 0.05
    momentum: float = 0.9
    optimizer: str = "adam"
    steps: int = 100_000
    eps0: float = 0.5
    k0: float = 100.0
    gamma: float = 0.75
    box: Box = Box(-2.0, 2.0, -2.0, 2.0)
    init_gain: float = 1.0

    def __post_init__(self):
        require(self.method in METHODS, f"training method {self.method!r} unknown; known: {', '.join(METHODS)}")
        require(self.epochs >= 1 and self.batch_size >= 1 and self.steps >= 1,
                "training: epochs, batch_size and steps must be positive")
        require(self.lr > 0 and self.eps0 > 0, "training: step sizes must be positive")
        require(0.5 < self.gamma <= 1.0, f"training: gamma={self.gamma} violates (A4); need 1/2 < gamma <= 1")
        require(0.0 <= self.momentum < 1.0, "training: momentum must lie in [0, 1)")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["box"] = list(self.box)
        return d


def sample_loss(params, x, y, noise, physics: Physics, arch: Architecture):
    """Mean over the batch of (y - M_s(x, w, N))^2; x (B, d_0), y (B, d_L), noise (B, ...)."""
    out = forward(params, x, noise, physics, arch).y
    return jnp.mean(squared_error(out, y))


def _batch_grad(params, key, xb, yb, physics, arch):
    noise = sample_noise(key, arch, physics, (xb.shape[0],), params[0].W.dtype)
    return jax.value_and_grad(sample_loss)(params, xb, yb, noise, physics, arch)


class Pinned(NamedTuple):
    """Entries of the weights held at fixed values while training (a device's stuck weights or dead
    neurons): ``mask`` and ``value`` are pytrees like the weights; where ``mask`` is true the entry
    is ``value``'s, whatever the step says (masked training)."""

    mask: tuple
    value: tuple


def pin(params, pinned: Pinned | None):
    """``params`` with the entries ``pinned`` holds set to its values (unchanged for None)."""
    if pinned is None:
        return params
    return jax.tree_util.tree_map(lambda p, m, v: jnp.where(m, jnp.asarray(v, p.dtype), p), params, pinned.mask,
                                  pinned.value)


@partial(jax.jit, static_argnames=("arch", "batch_size", "tx"))
def _epoch(params, opt_state, key, x, y, physics, arch, batch_size, tx, pinned=None):
    n = x.shape[0]
    n_batches = n // batch_size
    k_perm, k_noise = jax.random.split(key)
    perm = jax.random.permutation(k_perm, n)[: n_batches * batch_size].reshape(n_batches, batch_size)

    def step(carry, inp):
        p, s = carry
        idx, i = inp
        loss, g = _batch_grad(p, jax.random.fold_in(k_noise, i), x[idx], y[idx], physics, arch)
        updates, s = tx.update(g, s, p)
        return (pin(optax.apply_updates(p, updates), pinned), s), loss

    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), (perm, jnp.arange(n_batches)))
    return params, opt_state, jnp.mean(losses)


@functools.lru_cache(maxsize=64)
def _transform(config: TrainConfig):
    """The optax transform of ``config`` (cached: the same object keeps the compiled epoch)."""
    if config.method == "minibatch":
        return optax.sgd(config.lr, momentum=config.momentum or None)
    name = config.optimizer
    require(hasattr(optax, name), f"training: optax has no optimiser {name!r}")
    return getattr(optax, name)(config.lr)


def minibatch_sgd(key, params, x, y, physics: Physics, arch: Architecture, config: TrainConfig,
                  progress: Callable | None = None, pinned: Pinned | None = None):
    """The practical variant: ``config.epochs`` shuffled passes of mini-batch steps, no projection.
    ``pinned``: entries held at fixed values (:class:`Pinned`).

    Returns ``(params, epoch_losses)``.
    """
    tx = _transform(config)
    params = pin(params, pinned)
    opt_state = tx.init(params)
    x = jnp.asarray(x, params[0].W.dtype)
    y = jnp.asarray(y, params[0].W.dtype)
    bs = min(config.batch_size, x.shape[0])
    losses = []
    for epoch in range(config.epochs):
        params, opt_state, loss = _epoch(params, opt_state, jax.random.fold_in(key, epoch), x, y, physics, arch, bs, tx,
                                         pinned)
        losses.append(float(loss))
        if progress is not None:
            progress(epoch + 1, config.epochs, losses[-1])
    return params, np.asarray(losses)


def robbins_monro(k, eps0: float, k0: float, gamma: float):
    """eps_k = eps0 / (k0 + k)^gamma; (A4) holds for 1/2 < gamma <= 1."""
    return eps0 / (k0 + k) ** gamma


@partial(jax.jit, static_argnames=("arch", "steps", "sampler"))
def _projected_sgd(params, key, physics, arch, steps, sampler, eps0, k0, gamma, box):
    def step(p, k):
        kd, kn = jax.random.split(jax.random.fold_in(key, k))
        xk, yk = sampler(kd)
        noise = sample_noise(kn, arch, physics, (1,), p[0].W.dtype)
        loss, g = jax.value_and_grad(sample_loss)(p, xk[None], yk[None], noise, physics, arch)
        eps = robbins_monro(k, eps0, k0, gamma)
        p = project(jax.tree_util.tree_map(lambda a, b: a - eps * b, p, g), box)
        return p, loss

    return jax.lax.scan(step, params, jnp.arange(steps))


def projected_sgd(key, params, sampler: Callable, physics: Physics, arch: Architecture, config: TrainConfig):
    """eq. projected-sgd: ``config.steps`` single-sample steps, each projected onto the box H.

    Parameters
    ----------
    sampler : ``key -> (x, y)`` one data sample (x (d_0,), y (d_L,)); a hashable function
        (module-level or :func:`empirical_sampler`) so the compiled loop is reused.

    Returns ``(params, per-step losses)``.
    """
    params = project(params, config.box)
    params, losses = _projected_sgd(params, key, physics, arch, int(config.steps), sampler,
                                    config.eps0, config.k0, config.gamma, config.box)
    return params, np.asarray(losses)


@dataclasses.dataclass(frozen=True, eq=False)
class empirical_sampler:
    """Uniform draws with replacement from a finite data set (the empirical measure mu)."""

    x: object
    y: object

    def __call__(self, key):
        i = jax.random.randint(key, (), 0, self.x.shape[0])
        return self.x[i], self.y[i]


def train(key, arch: Architecture, x, y, physics: Physics, config: TrainConfig = TrainConfig(), *,
          params=None, dtype=jnp.float32, progress: Callable | None = None, pinned: Pinned | None = None):
    """Train M_s on (x, y) with noise ``physics`` (noise-aware at s0 = physics.s).

    Parameters
    ----------
    key : PRNG key (initialisation and all sampling derive from it)
    x : (n, d_0), y : (n, d_L) targets (one-hot for classification)
    params : starting weights (default: Glorot initialisation from ``key``)
    pinned : entries held at fixed values throughout (:class:`Pinned`; mini-batch and optax methods)

    Returns
    -------
    params : tuple of Layer
    """
    return train_with_history(key, arch, x, y, physics, config, params=params, dtype=dtype, progress=progress,
                              pinned=pinned)[0]


def train_with_history(key, arch, x, y, physics, config=TrainConfig(), *, params=None, dtype=jnp.float32,
                       progress=None, pinned=None):
    """:func:`train`, also returning the loss history (per epoch or per step)."""
    k_init, k_run = jax.random.split(key)
    if params is None:
        params = init_params(k_init, arch, dtype=dtype, gain=config.init_gain)
    if config.method == "projected_sgd":
        require(pinned is None, "training: pinned entries need the minibatch or optax method")
        sampler = empirical_sampler(jnp.asarray(x, dtype), jnp.asarray(y, dtype))
        return projected_sgd(k_run, params, sampler, physics, arch, config)
    return minibatch_sgd(k_run, params, x, y, physics, arch, config, progress, pinned)


def stderr_progress(label: str):
    """A progress callback for stderr: one rewritten line on a terminal, every 10 % otherwise."""
    t0 = time.perf_counter()
    tty = sys.stderr.isatty()

    def report(i, n, loss):
        if not tty and i != n and (i * 10) // n == ((i - 1) * 10) // n:
            return
        end = "\n" if (i == n or not tty) else "\r"
        sys.stderr.write(f"{label}: epoch {i}/{n}  loss {loss:.4f}  {time.perf_counter() - t0:5.1f}s{end}")
        sys.stderr.flush()

    return report
