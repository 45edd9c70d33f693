"""Small pytree algebra for directions shaped like the weights.

Each operation is one compiled program per weight structure: op by op, every leaf of every
shape would be its own tiny program (dozens of compilations per architecture)."""

from __future__ import annotations

import jax
import jax.numpy as jnp


@jax.jit
def axpy(a, x, y):
    """y + a x."""
    return jax.tree_util.tree_map(lambda xi, yi: yi + a * xi, x, y)


@jax.jit
def scale(a, x):
    return jax.tree_util.tree_map(lambda xi: a * xi, x)


@jax.jit
def vdot(x, y):
    return sum(jnp.vdot(a, b) for a, b in zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y)))


@jax.jit
def norm(x):
    return jnp.sqrt(vdot(x, x))


@jax.jit
def unit(x):
    n = norm(x)
    return scale(1.0 / jnp.where(n > 0, n, 1.0), x), n


@jax.jit
def zeros_like(x):
    return jax.tree_util.tree_map(jnp.zeros_like, x)
