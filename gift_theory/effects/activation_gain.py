"""``activation_gain``: the chip's nonlinearity has another slope, act(z) = sigma(kappa z)
on the hidden layers (a nonlinear element driven harder or softer than modelled;
reference §6 class ``activation_mismatch``). ``kappa = 1`` is the paper's model."""

from __future__ import annotations

import jax
import numpy as np

from ._base import Effect, register


@register
class ActivationGain(Effect):
    kappa: float | jax.Array = 1.0

    name = "activation_gain"
    params = ("kappa",)
    bounds = {"kappa": (0.05, 20.0)}
    defaults = {"kappa": 1.0}
    stage = "activation"
    mechanism = "activation_mismatch"
    layers = "hidden"
    description = "the hidden layers' nonlinearity is sigma(kappa z): another slope than modelled"

    def activation(self, z, sigma, layer):
        return sigma(self.kappa * z)

    @classmethod
    def signature(cls, res):
        d = res.mean_derivative("activation_gain", "kappa", 1.0, 1e-3)
        w = [dk / np.sqrt(vB + 1e-300) for dk, vB in zip(d, res.vB)]
        z = res.score(res.mean_resid, w)
        return {"statistic": "mean residual along the slope direction d(mean)/d kappa", "z": abs(z), "value": z}
