"""Monte-Carlo estimates of the objective J_s(w) and of the in-situ evaluation Eval_w.

Paper eqs. objective-function-as-a-function-of-s and def:Eval. Every estimate carries
its standard error; the hierarchical K1 x K2 design (K1 inputs, K2 noise draws each) is
summarised by the K1 per-input means, which are independent, so the standard error is
their standard deviation over sqrt(K1) (lem:Hierarchical-sampling-is-unbiased).
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._arch import Architecture
from . import _xla
from ._model import compiled_draws, forward, squared_error
from .effects import Physics


class Estimate(NamedTuple):
    """A Monte-Carlo estimate: ``mean`` with standard error ``se`` from ``n`` independent units.

    ``samples`` holds the per-unit values (here: per input, averaged over its K2 shots)
    when they were kept; tests derive tolerances from ``se``.
    """

    mean: Any
    se: Any
    n: int
    samples: Any = None

    def ci(self, z: float = 1.959964):
        """The normal-approximation confidence interval ``mean -/+ z se``."""
        return self.mean - z * self.se, self.mean + z * self.se

    def __format__(self, spec):
        spec = spec or ".4g"
        return f"{float(self.mean):{spec}} ± {float(self.se):{spec}}"


def estimate_from_samples(samples) -> Estimate:
    """Mean and standard error of independent per-unit values (axis 0)."""
    v = np.asarray(samples, dtype=np.float64)
    n = v.shape[0]
    se = v.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(v.shape[1:], np.inf)
    return Estimate(v.mean(axis=0), se, n, v)


def stack_weights(weight_sets):
    """Weight sets (tuples of Layer, same shapes) stacked on a new leading axis of every leaf."""
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *weight_sets)


@partial(_xla.jit, static_argnames=("arch",))
def _scores(noise, weight_sets, x, y, labels, physics, arch):
    # one pass per weight set over the same draws: vmapped, the first layer of every set is one
    # product with the shared noisy input; loss and correctness come from the same outputs.
    # The sets are stacked here, inside the program (op by op, a program per leaf shape)
    P = stack_weights(weight_sets)

    def one(p):
        out = forward(p, x[:, None, :].astype(p[0].W.dtype), noise, physics, arch).y
        loss = None if y is None else jnp.mean(squared_error(out, y[:, None, :]), axis=1)
        correct = None if labels is None else jnp.mean(jnp.argmax(out, axis=-1) == labels[:, None], axis=1)
        return loss, correct

    return jax.vmap(one)(P)


@partial(_xla.jit, static_argnames=("arch",))
def _slopes(noise, params, u, x, y, physics, arch):
    def loss(p):
        out = forward(p, x[:, None, :].astype(p[0].W.dtype), noise, physics, arch).y
        return jnp.mean(squared_error(out, y[:, None, :]), axis=1)

    return jax.jvp(loss, (params,), (u,))[1]


def _chunks(key, n: int, K2: int, chunk: int):
    """(subkey, start, stop) of every block of at most ``chunk`` samples: block i draws with fold_in(key, i)."""
    rows = max(1, chunk // max(K2, 1))
    return [(jax.random.fold_in(key, i), s, min(s + rows, n)) for i, s in enumerate(range(0, n, rows))]


def per_input_scores(key, weight_sets, x, y, labels, physics: Physics, arch: Architecture, K2: int = 1,
                     chunk: int = 4096):
    """Per-input loss and correctness of several weight sets on the same noise draws.

    For each weight set and input, the mean over K2 draws of (y - M_s(x, w, N))^2 and the
    fraction of the K2 draws whose output's argmax is the label. Every weight set sees the same
    draws (common random numbers), and both quantities come from one forward pass.

    Parameters
    ----------
    key : PRNG key; block i of at most ``chunk`` samples uses ``fold_in(key, i)`` (so one weight
        set gives exactly the losses of :func:`per_input_loss` with the same key)
    weight_sets : sequence of P weight tuples (same architecture)
    x : (K1, d_0); y : (K1, d_L) or None; labels : (K1,) ints or None
    K2 : noise draws per input

    Returns
    -------
    (losses, correct) : ndarrays of shape (P, K1) (None for a quantity whose targets are None)
    """
    weight_sets = tuple(weight_sets)
    dtype = jnp.dtype(weight_sets[0][0].W.dtype)
    x = np.asarray(x)
    y = None if y is None else np.asarray(y, dtype)
    labels = None if labels is None else np.asarray(labels)
    parts = []
    for k, a, b in _chunks(key, x.shape[0], K2, chunk):
        noise = compiled_draws(k, physics, arch=arch, shape=(b - a, K2), dtype=dtype)
        parts.append(_scores(noise, weight_sets, x[a:b], None if y is None else y[a:b],
                             None if labels is None else labels[a:b], physics, arch))
    # read back once at the end: the blocks are dispatched without waiting for each other
    losses = None if y is None else np.concatenate([np.asarray(p[0]) for p in parts], axis=1)
    correct = None if labels is None else np.concatenate([np.asarray(p[1]) for p in parts], axis=1)
    return losses, correct


def per_input_loss(key, params, x, y, physics: Physics, arch: Architecture, K2: int = 1,
                   chunk: int = 4096) -> np.ndarray:
    """For each input, the mean over K2 noise draws of (y - M_s(x, w, N))^2.

    Parameters
    ----------
    key : PRNG key (same key, same draws: pass the same key to compare weights with
        common random numbers)
    x : (K1, d_0), y : (K1, d_L)
    K2 : noise draws per input

    Returns
    -------
    ndarray of shape (K1,)
    """
    return per_input_scores(key, [params], x, y, None, physics, arch, K2, chunk)[0][0]


def directional_derivative(key, params, u, x, y, physics: Physics, arch: Architecture, K2: int = 1,
                           chunk: int = 4096) -> "Estimate":
    """d/da J_s(w + a u) at a = 0, i.e. <grad_w J_s(w), u>, by forward-mode autodiff per input.

    Same draws as :func:`per_input_loss` with the same key; ``u`` is a pytree like the weights.

    Returns
    -------
    Estimate whose samples are the K1 per-input slopes (mean over K2 draws each).
    """
    dtype = jnp.dtype(params[0].W.dtype)
    u = jax.tree_util.tree_map(lambda a, p: jnp.asarray(a, p.dtype), u, params)
    x = np.asarray(x)
    y = np.asarray(y, dtype)
    parts = []
    for k, a, b in _chunks(key, x.shape[0], K2, chunk):
        noise = compiled_draws(k, physics, arch=arch, shape=(b - a, K2), dtype=dtype)
        parts.append(_slopes(noise, params, u, x[a:b], y[a:b], physics, arch))
    return estimate_from_samples(np.concatenate([np.asarray(p) for p in parts]))


def objective(key, params, x, y, physics: Physics, arch: Architecture, K2: int = 1) -> Estimate:
    """J_s(w) estimated on the inputs ``x`` with K2 draws each (eq. objective-function-as-a-function-of-s).

    Returns an :class:`Estimate` whose samples are the K1 per-input means.
    """
    return estimate_from_samples(per_input_loss(key, params, x, y, physics, arch, K2))


def paired_difference(key, params_a, params_b, x, y, physics: Physics, arch: Architecture, K2: int = 1,
                      chunk: int = 4096) -> Estimate:
    """J(w_a) - J(w_b) with common random numbers (same inputs, same draws; ``chunk``: samples per
    block of draws, as in :func:`per_input_scores`)."""
    losses = per_input_scores(key, [params_a, params_b], x, y, None, physics, arch, K2, chunk)[0]
    return estimate_from_samples(losses[0] - losses[1])


def eval_from_outputs(outputs, y) -> Estimate:
    """Eval_w(K1, K2) (eq. def:Eval) from measured outputs.

    Parameters
    ----------
    outputs : (K1, K2, d_L) measured shots
    y : (K1, d_L) targets
    """
    outputs = np.asarray(outputs, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    per_input = np.sum((outputs - y[:, None, :]) ** 2, axis=-1).mean(axis=1)
    return estimate_from_samples(per_input)


def accuracy(key, params, x, labels, physics: Physics, arch: Architecture, K2: int = 1,
             chunk: int = 4096) -> Estimate:
    """Classification accuracy by argmax of the noisy output, with its standard error."""
    return estimate_from_samples(per_input_scores(key, [params], x, None, labels, physics, arch, K2, chunk)[1][0])
