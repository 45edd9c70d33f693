"""``common_mode``: gain g_l = 1 + c xi_l, one xi_l per layer per shot, shared by all
neurons of the layer (laser intensity noise)."""

from __future__ import annotations

import jax

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
