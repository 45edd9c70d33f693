"""``layer_gain``: one fixed gain g_l per layer, fixed per device, W_l^eff = g_l W_l (optical
insertion loss, detector responsivity; reference §2, §6 class ``gain_error``).

The parameter ``g`` is per layer (``shape = {"g": "layers"}``): a number (the same gain on
every layer, as ``layer_gain=0.6`` on the command line gives) or one value per layer, held as
a (1,)-array per layer (``Physics.create(layer_gain=dict(g=((0.6,), (0.8,), (1.1,))))``). It
acts as the last weights hook (``order``), so with other weights effects W_eff = g_l (W_l + ...):
the gain of the whole weighted sum, and it multiplies any gain of the gain stage. A fit
(:mod:`gift_theory.lab._fit_moments`) reads one coordinate per layer.
"""

from __future__ import annotations

import jax
import numpy as np

from ._base import Effect, register


@register
class LayerGain(Effect):
    g: float | jax.Array | tuple = 1.0

    name = "layer_gain"
    params = ("g",)
    shape = {"g": "layers"}
    bounds = {"g": (0.0, float("inf"))}
    defaults = {"g": 1.0}
    stage = "weights"
    # after the other weights hooks: g multiplies the whole fixed map, W_eff = g (W + E)
    order = 9
    mechanism = "gain_error"
    description = "a fixed gain g_l on each layer's weighted sum, W_eff = g_l W (optical loss, responsivity)"

    def weights(self, W, layer):
        # a per-layer value is a (1,)-array: it broadcasts against W (d_l, d_{l-1})
        return self.value("g", layer) * W

    @classmethod
    def search(cls, param, layers):
        # a loss or a responsivity of up to a factor 5 either way, 4 % apart (log scale)
        return np.geomspace(0.2, 5.0, 41)

    @classmethod
    def signature(cls, res):
        # each measured layer's mean residual along the direction a gain on its weighted sum moves
        # it (sigma'(z) u); one chi-square over the layers (a gain may go either way per layer)
        from scipy import stats

        zs = [res.score(e, g / np.sqrt(vB + 1e-300)) for e, g, vB in zip(res.mean_resid, res.gain_dir, res.vB)]
        q, df = float(np.sum(np.square(zs))), len(zs)
        z = float(stats.norm.isf(max(stats.chi2.sf(q, df=df), 1e-300)))
        return {"statistic": f"mean residual along each layer's gain direction sigma'(z) u (chi-square of {df} layers)",
                "z": z, "value": q / max(df, 1)}
