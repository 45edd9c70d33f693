"""``shot``: the readout adds sqrt(q |v|) xi to each value v (variance proportional to
the signal; second link of D)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, register


def safe_sqrt(x):
    """sqrt with a finite gradient at 0 (the double-where trick)."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


@register
class Shot(Effect):
    q: float | jax.Array = 0.01

    name = "shot"
    params = ("q",)
    bounds = {"q": (0.0, float("inf"))}
    defaults = {"q": 0.01}
    stage = "readout"
    mechanism = "input_dependent_noise"
    order = 1
    description = "signal-dependent readout noise of variance q |v|"

    def draws(self, arch):
        return {f"shot{l}": (arch.widths[l],) for l in range(1, arch.depth + 1)}

    def readout(self, v, noise, layer):
        return v + safe_sqrt(self.q * jnp.abs(v)) * noise[f"shot{layer}"]

    @classmethod
    def signature(cls, res):
        w = [np.abs(m) for m in res.mB]
        return {"statistic": "excess variance along |mean| (shot: variance q |v|)", "z": res.score(res.var_resid, w),
                "value": float(np.mean([np.mean(v) for v in res.var_resid]))}
