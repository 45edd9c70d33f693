"""``multiplicative``: gain g_l = 1 + m xi, one xi per neuron per shot (phase-shifter
or modulator noise scaling the optical weighted sum)."""

from __future__ import annotations

import jax
import numpy as np

from ._base import Effect, register


@register
class Multiplicative(Effect):
    m: float | jax.Array = 0.05

    name = "multiplicative"
    params = ("m",)
    bounds = {"m": (0.0, float("inf"))}
    defaults = {"m": 0.05}
    stage = "gain"
    mechanism = "input_dependent_noise"
    description = "per-neuron per-shot gain 1 + m xi on the weighted sum"

    def draws(self, arch):
        return {f"mult{l}": (arch.widths[l],) for l in range(1, arch.depth + 1)}

    def gain(self, noise, layer, t, shape):
        return 1.0 + self.m * noise[f"mult{layer}"]

    @classmethod
    def signature(cls, res):
        w = [m ** 2 for m in res.mB]
        return {"statistic": "excess variance along mean^2 (multiplicative: variance m^2 u^2)",
                "z": res.score(res.var_resid, w), "value": float(np.mean([np.mean(v) for v in res.var_resid]))}
