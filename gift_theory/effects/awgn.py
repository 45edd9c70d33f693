"""``awgn``: the baseline additive noise n_a0, n_wl, n_al ~ N(0, s^2) (paper eq.
Normally-distributed-noise-matrices). Its ``s`` is the noise level of every additive
site; ``laplace`` and ``uniform`` change the law, never the standard deviation."""

from __future__ import annotations

import jax
import numpy as np

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

    @classmethod
    def search(cls, param, layers):
        """s is scanned relative to the data's own scale, not from a fixed floor: 16 log-spaced
        values over [sd / 100, 2 sd], sd the rms within-input spread of the measured layers
        (each noise site adds s^2 to a layer's variance, the weighted sum and its input noise
        more: s lies below sd, by at most ~10 for a layer whose |W_row|^2 is 100). Data with no
        spread at all fall back on the default scan."""
        if param == "s" and layers:
            v = [float(np.mean(np.var(np.asarray(a, np.float64), axis=1, ddof=1))) for a in layers if a.shape[1] > 1]
            sd = float(np.sqrt(np.mean(v))) if v else 0.0
            if np.isfinite(sd) and sd > 0:
                return np.geomspace(sd / 100.0, 2.0 * sd, 16)
        return super().search(param, layers)
