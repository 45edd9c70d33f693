"""``weight_error``: W_eff = W + E_l, E_l iid N(0, e^2) drawn once per device and fixed
(fabrication / mapping error). The device is named by ``seed`` (static): the same seed
is the same device, another seed another device."""

from __future__ import annotations

import jax
import numpy as np

from .. import _random
from ._base import Effect, register


def device_draw(seed: int, layer: int, shape, dtype):
    """The standard-normal E_l / e of device ``seed`` (fixed for the device's life)."""
    key = jax.random.fold_in(jax.random.PRNGKey(int(seed)), 1_000_003 + layer)
    return _random.normal_like_jax(key, shape, dtype)


@register
class WeightError(Effect):
    e: float | jax.Array = 0.02
    seed: int = 0

    name = "weight_error"
    params = ("e",)
    bounds = {"e": (0.0, float("inf"))}
    defaults = {"e": 0.02}
    stage = "weights"
    mechanism = "weight_error"
    order = 1
    static_fields = ("seed",)
    offsets_of = "W"
    description = "a fixed per-device error E ~ N(0, e^2) added to every weight"

    def weights(self, W, layer):
        return W + self.e * device_draw(self.seed, layer, W.shape, W.dtype)

    @classmethod
    def signature(cls, res):
        # offsets fixed per device repeat in both halves of the shots; noise does not
        T = 0.0
        for Y, mA, mB, vB, k in zip(res.Y, res.mA, res.mB, res.vB, res.model_half_shots()):
            h = Y.shape[1] // 2
            se = np.sqrt(vB * (1.0 / max(h, 1) + 1.0 / k) + 1e-300)
            ra = (Y[:, :h].mean(1) - mA) / se
            rb = (Y[:, h:2 * h].mean(1) - mB) / se
            T = T + np.sum(ra * rb, axis=1)
        return {"statistic": "split-half reproducibility of the mean residuals (products of two halves' residuals)",
                "z": res.over_inputs(T), "value": float(np.mean(T))}
