"""``drift``: gain g_l = 1 + r t, t in [0, 1] the shot's normalised acquisition time
(reference §6 class ``time_drift``: a parameter that changes over the acquisition time).
Without acquisition times t = 0 and the effect is silent."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._base import Effect, register


@register
class Drift(Effect):
    r: float | jax.Array = 0.05

    name = "drift"
    params = ("r",)
    defaults = {"r": 0.05}
    stage = "gain"
    mechanism = "time_drift"
    order = 2
    needs_times = True
    description = "gain 1 + r t drifting linearly with the acquisition time t"

    def gain(self, noise, layer, t, shape):
        if t is None:
            return 1.0
        return 1.0 + self.r * jnp.asarray(t)[..., None]

    @classmethod
    def signature(cls, res):
        if res.t is None:
            return {"statistic": "no acquisition times in the file: drift is silent", "z": float("nan"),
                    "value": float("nan"), "stands_out": False}
        tc = (res.t.mean(1) - res.t.mean())[:, None]
        z = res.score(res.mean_resid, [tc * m for m in res.mB])
        return {"statistic": "mean residual along t * mean (gain 1 + r t)", "z": abs(z), "value": z}
