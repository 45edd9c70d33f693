"""``quantization``: the readout maps v to clip(round(v / step) step, -v_range, v_range),
step = 2 v_range / 2^bits (last link of D)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._base import Effect, register


@register
class Quantization(Effect):
    bits: float | jax.Array = 8.0
    v_range: float | jax.Array = 2.0

    name = "quantization"
    params = ("bits", "v_range")
    bounds = {"bits": (1.0, 32.0), "v_range": (1e-12, float("inf"))}
    defaults = {"bits": 8.0, "v_range": 2.0}
    stage = "readout"
    mechanism = "readout_nonlinearity"
    order = 2
    description = "uniform ADC of `bits` bits on [-v_range, v_range]"

    @property
    def step(self):
        return 2.0 * self.v_range / 2.0 ** jnp.round(self.bits)

    def readout(self, v, noise, layer):
        step = self.step
        return jnp.clip(jnp.round(v / step) * step, -self.v_range, self.v_range)
