"""``crosstalk``: W_eff[i, j] = W[i, j] + k (W[i, j-1] + W[i, j+1]), zero outside the
row (thermal crosstalk of neighbouring heaters)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, register


def neighbour_sum(W: jax.Array) -> jax.Array:
    """``N[i, j] = W[i, j-1] + W[i, j+1]`` with zeros outside the row."""
    pad = jnp.pad(W, ((0, 0), (1, 1)))
    return pad[:, :-2] + pad[:, 2:]


@register
class Crosstalk(Effect):
    k: float | jax.Array = 0.02

    name = "crosstalk"
    params = ("k",)
    defaults = {"k": 0.02}
    stage = "weights"
    mechanism = "weight_error"
    description = "each weight picks up k times its two row neighbours"

    def weights(self, W, layer):
        return W + self.k * neighbour_sum(W)

    @classmethod
    def signature(cls, res):
        d = res.mean_derivative("crosstalk", "k", 0.0, 1e-3)
        w = [dk / np.sqrt(vB + 1e-300) for dk, vB in zip(d, res.vB)]
        z = res.score(res.mean_resid, w)
        return {"statistic": "mean residual along the neighbour-weight direction d(mean)/dk", "z": abs(z), "value": z}
