"""Hierarchical K1 x K2 Monte Carlo over pytree-valued quantities, chunked, with standard errors.

Paper lem:Hierarchical-sampling-is-unbiased: K1 inputs, K2 noise draws each. A pytree-valued
estimate (a direction like the weights) cannot keep one value per input on a large net
(K1 x n_params floats), so the K1 inputs are dealt round-robin into G groups ("batch
means"): the group sums are independent, and the standard error of the overall mean is the
ratio estimator over the groups,

    mean = sum_g S_g / K1,     se^2 = G / (G - 1) * sum_g (S_g - n_g mean)^2 / K1^2,

with S_g the sum over the n_g inputs of group g of their per-input mean over K2 draws. With
G = K1 this is the usual per-input standard error. The work is done in blocks of at most
``chunk`` samples (inputs x draws), so memory does not grow with K1 K2.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import require
from .._objective import Estimate


class Plan:
    """How K1 inputs are laid out into groups and blocks (static)."""

    def __init__(self, K1: int, K2: int, groups: int, chunk: int):
        require(K1 >= 1, f"estimator: need at least one input, got K1={K1}")
        require(K2 >= 1, f"estimator: K2 must be a positive integer, got {K2}")
        require(groups >= 1, f"estimator: groups must be positive, got {groups}")
        require(chunk >= 1, f"estimator: chunk must be positive, got {chunk}")
        self.K1, self.K2 = int(K1), int(K2)
        self.G = min(int(groups), self.K1)
        m = math.ceil(self.K1 / self.G)
        self.msub = max(1, min(m, chunk // self.K2))
        self.nsub = math.ceil(m / self.msub)
        self.m = self.nsub * self.msub
        self.B = max(1, min(self.G, chunk // (self.msub * self.K2)))
        self.Gpad = math.ceil(self.G / self.B) * self.B
        idx = np.full((self.Gpad, self.m), -1, dtype=np.int64)
        i = np.arange(self.K1)
        idx[i % self.G, i // self.G] = i  # round robin: group sizes differ by at most one
        self.index = idx
        self.n_g = (idx >= 0).sum(axis=1)[: self.G]


def hierarchical_mean(block_fn: Callable, key, x, y, *, K2: int, groups: int = 16, chunk: int = 16384,
                      keep_samples: bool = False, block_args=()) -> Estimate:
    """Average a per-sample pytree quantity over K1 inputs x K2 draws, with its standard error.

    Parameters
    ----------
    block_fn : callable ``(key, xb, yb, wb, *block_args) -> pytree`` (jitted by the caller)
        ``xb`` (B, m, d_0), ``yb`` (B, m, d_L), ``wb`` (B, m) input weights (1, or 0 for
        padding), ``key`` for the block's K2 draws per input; returns per-group sums
        ``sum_i wb_i mean_m q(x_i, N_im)`` with a leading axis B on every leaf.
    key : PRNG key; block ``c`` uses ``fold_in(key, c)`` (same key, same draws)
    x : (K1, d_0); y : (K1, d_L)
    K2 : draws per input; groups : G, the number of independent units; chunk : samples per block

    Returns
    -------
    Estimate with ``mean``/``se`` pytrees like the quantity, ``n = G`` and, if asked,
    ``samples`` = per-group means (leading axis G).
    """
    x = jnp.asarray(x)
    y = jnp.asarray(y)
    plan = Plan(x.shape[0], K2, groups, chunk)
    safe = np.maximum(plan.index, 0)
    ww = np.asarray(plan.index >= 0, dtype=x.dtype)
    sums = []
    call = 0
    for g0 in range(0, plan.Gpad, plan.B):
        acc = None
        for s0 in range(0, plan.m, plan.msub):
            sl = (slice(g0, g0 + plan.B), slice(s0, s0 + plan.msub))
            # gather one block's inputs at a time: memory stays at one block, whatever K1
            out = block_fn(jax.random.fold_in(key, call), *_take(x, y, safe[sl]), jnp.asarray(ww[sl]), *block_args)
            call += 1
            acc = out if acc is None else _add(acc, out)
        sums.append(acc)
    one = len(sums) == 1 and plan.Gpad == plan.G  # one block holding every group: nothing to stack
    return summarise(sums[0] if one else _groups(tuple(sums), plan.G), plan.n_g, keep_samples)


# the bookkeeping compiled: op by op, jnp's fancy indexing with a numpy index and a
# concatenate per leaf cost ~15 ms of Python per call, a tenth of an estimate on the deep net
@jax.jit
def _take(x, y, idx):
    return x[idx], y[idx]


@jax.jit
def _add(a, b):
    return jax.tree_util.tree_map(jnp.add, a, b)


@partial(jax.jit, static_argnames=("G",))
def _groups(sums, G):
    return jax.tree_util.tree_map(lambda *a: jnp.concatenate(a, axis=0)[:G], *sums)


def summarise(S, n_g, keep_samples: bool = False) -> Estimate:
    """Ratio-estimator mean and standard error from group sums ``S`` (leading axis G)."""
    n_g = np.asarray(n_g, dtype=np.float64)
    mean, se, samples = _summarise(S, jnp.asarray(n_g), float(n_g.sum()), bool(keep_samples))
    return Estimate(mean, se, int(n_g.shape[0]), samples)


@partial(jax.jit, static_argnames=("K1", "keep_samples"))
def _summarise(S, n_g, K1, keep_samples):
    G = n_g.shape[0]

    def nb(s):
        return n_g.astype(s.dtype).reshape((-1,) + (1,) * (s.ndim - 1))

    # sums over the group axis as scans: XLA's CPU reduction over a leading axis is ~20x slower
    def total(s):
        return jax.lax.scan(lambda c, v: (c + v, None), jnp.zeros_like(s[0]), s)[0]

    def mean(s):
        return total(s) / K1

    def se(s):
        if G < 2:
            return jnp.full(s.shape[1:], jnp.inf, s.dtype)
        mu = mean(s)
        dev = jax.lax.scan(lambda c, v: (c + (v[0] - v[1] * mu) ** 2, None), jnp.zeros_like(mu),
                           (s, n_g.astype(s.dtype)))[0]
        return jnp.sqrt(dev * (G / (G - 1))) / K1

    samples = jax.tree_util.tree_map(lambda s: s / nb(s), S) if keep_samples else None
    return jax.tree_util.tree_map(mean, S), jax.tree_util.tree_map(se, S), samples
