"""``common_mode``: gain g_l = 1 + c xi_l, one xi_l per layer per shot, shared by all
neurons of the layer (laser intensity noise)."""

from __future__ import annotations

import jax
import numpy as np

from ._base import Effect, register


@register
class CommonMode(Effect):
    c: float | jax.Array = 0.05

    name = "common_mode"
    params = ("c",)
    bounds = {"c": (0.0, float("inf"))}
    defaults = {"c": 0.05}
    stage = "gain"
    mechanism = "gain_fluctuation"
    order = 1
    description = "per-layer per-shot gain 1 + c xi shared by the layer's neurons (laser intensity noise)"

    def draws(self, arch):
        return {f"cm{l}": () for l in range(1, arch.depth + 1)}

    def gain(self, noise, layer, t, shape):
        return 1.0 + self.c * noise[f"cm{layer}"][..., None]

    @classmethod
    def signature(cls, res):
        def unit(m):
            return m / np.sqrt(np.sum(m ** 2, axis=1, keepdims=True) + 1e-300)

        def excess(S, w):
            return np.var(np.einsum("nkd,nd->nk", S, w), axis=1, ddof=1) - np.sum(w ** 2 * S.var(1, ddof=1), 1)

        # a common gain adds c^2 u_j u_k to every covariance: the variance of the shots projected
        # on the mean direction beyond the sum of the per-neuron variances
        T = 0.0
        model = res.per_input_of_model_halves(lambda li, sl, MA, MB: excess(MA, unit(res.mB[li][sl])))
        for Y, mB, vB, m in zip(res.Y, res.mB, res.vB, model):
            w = unit(mB)
            T = T + (excess(Y, w) - m) / (np.sum(w ** 2 * vB, 1) + 1e-300)
        return {"statistic": "excess covariance along the mean direction (the rank-one part a common gain adds)",
                "z": res.over_inputs(T), "value": float(np.mean(T))}
