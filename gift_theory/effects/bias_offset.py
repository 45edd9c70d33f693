"""``bias_offset``: b_eff = b + delta_l, delta_l[i] ~ N(0, sigma^2) iid per neuron, drawn
once per device and fixed (a fabrication / calibration offset of each neuron's
pre-activation; reference §6 class ``bias_offset``). Like ``weight_error``, the device is
named by ``seed`` (static): the same seed is the same device, another seed another
device. Its draws are independent of ``weight_error``'s for the same seed."""

from __future__ import annotations

import jax
import numpy as np

from .. import _random
from ._base import Effect, register

#: fold_in offset of the device stream (weight_error's is 1_000_003: the streams differ)
STREAM = 2_000_003


def device_draw(seed: int, layer: int, shape, dtype):
    """The standard-normal delta_l / sigma of device ``seed`` (fixed for the device's life)."""
    key = jax.random.fold_in(jax.random.PRNGKey(int(seed)), STREAM + layer)
    return _random.normal_like_jax(key, shape, dtype)


@register
class BiasOffset(Effect):
    sigma: float | jax.Array = 0.05
    seed: int = 0

    name = "bias_offset"
    params = ("sigma",)
    bounds = {"sigma": (0.0, float("inf"))}
    defaults = {"sigma": 0.05}
    stage = "bias"
    mechanism = "bias_offset"
    static_fields = ("seed",)
    offsets_of = "b"
    description = "a fixed per-device offset delta ~ N(0, sigma^2) added to every neuron's bias"

    def bias(self, b, layer):
        return b + self.sigma * device_draw(self.seed, layer, b.shape[-1:], b.dtype)

    @classmethod
    def signature(cls, res):
        # a fixed shift per neuron: each neuron's mean residual has the same sign on every input
        zs = []
        for e in res.mean_resid:
            m, sd = e.mean(0), e.std(0, ddof=1) / np.sqrt(e.shape[0])
            zs.append(m / np.maximum(sd, 1e-300))
        q = float(np.sum(np.concatenate(zs) ** 2))
        df = sum(len(z) for z in zs)
        from scipy import stats
        z = float(stats.norm.isf(max(stats.chi2.sf(q, df=df), 1e-300)))
        return {"statistic": f"per-neuron constant mean residual (chi-square of {df} neuron means)", "z": z,
                "value": q / max(df, 1)}
