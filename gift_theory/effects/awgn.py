"""``awgn``: the baseline additive noise n_a0, n_wl, n_al ~ N(0, s^2) (paper eq.
Normally-distributed-noise-matrices). Its ``s`` is the noise level of every additive
site; ``laplace`` and ``uniform`` change the law, never the standard deviation."""

from __future__ import annotations

import jax

from ._base import Effect, register


def additive_sites(arch) -> dict[str, tuple[int, ...]]:
    """The additive noise sites of ``arch``: ``a0``, ``w1..wL``, ``a1..a{L-1}``."""
    sites = {"a0": (arch.widths[0],)}
    if arch.noise_sites == "all":
        for l in range(1, arch.depth + 1):
            sites[f"w{l}"] = (arch.widths[l],)
            if l < arch.depth:
                sites[f"a{l}"] = (arch.widths[l],)
    return sites


@register
class Awgn(Effect):
    s: float | jax.Array = 0.1

    name = "awgn"
    params = ("s",)
    bounds = {"s": (0.0, float("inf"))}
    defaults = {"s": 0.1}
    stage = "level"
    mechanism = "noise_level"
    description = "additive noise of standard deviation s at input, weighted sums and hidden activations"

    def draws(self, arch):
        return additive_sites(arch)
