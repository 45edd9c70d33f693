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
from ._model import forward, sample_noise, squared_error
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


@partial(jax.jit, static_argnames=("arch", "K2"))
def _per_input_loss(key, params, x, y, physics, arch, K2):
    noise = sample_noise(key, arch, physics, (x.shape[0], K2), params[0].W.dtype)
    out = forward(params, x[:, None, :].astype(params[0].W.dtype), noise, physics, arch).y
    return jnp.mean(squared_error(out, y[:, None, :]), axis=1)


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
    x = jnp.asarray(x)
    y = jnp.asarray(y)
    rows = max(1, chunk // max(K2, 1))
    parts = []
    for i, start in enumerate(range(0, x.shape[0], rows)):
        k = jax.random.fold_in(key, i)
        parts.append(np.asarray(_per_input_loss(k, params, x[start:start + rows], y[start:start + rows],
                                                physics, arch, K2)))
    return np.concatenate(parts)


def objective(key, params, x, y, physics: Physics, arch: Architecture, K2: int = 1) -> Estimate:
    """J_s(w) estimated on the inputs ``x`` with K2 draws each (eq. objective-function-as-a-function-of-s).

    Returns an :class:`Estimate` whose samples are the K1 per-input means.
    """
    return estimate_from_samples(per_input_loss(key, params, x, y, physics, arch, K2))


def paired_difference(key, params_a, params_b, x, y, physics: Physics, arch: Architecture, K2: int = 1) -> Estimate:
    """J(w_a) - J(w_b) with common random numbers (same inputs, same draws)."""
    la = per_input_loss(key, params_a, x, y, physics, arch, K2)
    lb = per_input_loss(key, params_b, x, y, physics, arch, K2)
    return estimate_from_samples(la - lb)


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


@partial(jax.jit, static_argnames=("arch", "K2"))
def _per_input_correct(key, params, x, labels, physics, arch, K2):
    noise = sample_noise(key, arch, physics, (x.shape[0], K2), params[0].W.dtype)
    out = forward(params, x[:, None, :].astype(params[0].W.dtype), noise, physics, arch).y
    return jnp.mean(jnp.argmax(out, axis=-1) == labels[:, None], axis=1)


def accuracy(key, params, x, labels, physics: Physics, arch: Architecture, K2: int = 1,
             chunk: int = 4096) -> Estimate:
    """Classification accuracy by argmax of the noisy output, with its standard error."""
    x = jnp.asarray(x)
    labels = jnp.asarray(labels)
    rows = max(1, chunk // max(K2, 1))
    parts = [np.asarray(_per_input_correct(jax.random.fold_in(key, i), params, x[s:s + rows], labels[s:s + rows],
                                           physics, arch, K2))
             for i, s in enumerate(range(0, x.shape[0], rows))]
    return estimate_from_samples(np.concatenate(parts))
