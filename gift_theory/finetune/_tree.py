"""Small pytree algebra for directions shaped like the weights."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def axpy(a, x, y):
    """y + a x."""
    return jax.tree_util.tree_map(lambda xi, yi: yi + a * xi, x, y)


def scale(a, x):
    return jax.tree_util.tree_map(lambda xi: a * xi, x)


def vdot(x, y):
    return sum(jnp.vdot(a, b) for a, b in zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y)))


def norm(x):
    return jnp.sqrt(vdot(x, x))


def unit(x):
    n = norm(x)
    return scale(1.0 / jnp.where(n > 0, n, 1.0), x), n


def zeros_like(x):
    return jax.tree_util.tree_map(jnp.zeros_like, x)
