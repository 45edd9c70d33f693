"""``saturation``: the readout maps v to v_max tanh(v / v_max) (first link of D)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, register


@register
class Saturation(Effect):
    v_max: float | jax.Array = 2.0

    name = "saturation"
    params = ("v_max",)
    bounds = {"v_max": (1e-12, float("inf"))}
    defaults = {"v_max": 2.0}
    stage = "readout"
    mechanism = "readout_nonlinearity"
    order = 0
    description = "soft readout saturation v_max tanh(v / v_max)"

    def readout(self, v, noise, layer):
        return self.v_max * jnp.tanh(v / self.v_max)

    @classmethod
    def search(cls, param, layers):
        vmax = max(float(np.max(np.abs(a))) for a in layers)
        return np.geomspace(0.3 * vmax, 30 * vmax, 17)

    @classmethod
    def signature(cls, res):
        w = [-(m ** 3) for m in res.mB]
        return {"statistic": "mean residual along -mean^3 (compression of large values)",
                "z": res.score(res.mean_resid, w), "value": float("nan")}
