"""``laplace``: the additive noise n_* is Laplace with standard deviation s (scale
s / sqrt(2)) instead of Gaussian. No parameter of its own: it uses ``awgn``'s s."""

from __future__ import annotations

import numpy as np

from .. import _random
from ._base import Effect, register


@register
class Laplace(Effect):
    name = "laplace"
    stage = "law"
    mechanism = "noise_law"
    description = "additive noise drawn from a Laplace law with standard deviation s"

    @staticmethod
    def standard(key, shape, dtype):
        """Unit-variance Laplace draws."""
        return _random.laplace(key, shape, dtype)

    @classmethod
    def signature(cls, res):
        T = sum(np.sum(k, axis=1) for k in res.kurt_resid)
        return {"statistic": "excess kurtosis of the shots above the model's at equal size (Laplace > 0)",
                "z": res.over_inputs(T), "value": float(np.mean(T))}
