"""``uniform``: the additive noise n_* is Uniform(-sqrt(3) s, sqrt(3) s) (standard
deviation s). No parameter of its own: it uses ``awgn``'s s."""

from __future__ import annotations

import numpy as np

from .. import _random
from ._base import Effect, register


@register
class Uniform(Effect):
    name = "uniform"
    stage = "law"
    mechanism = "noise_law"
    order = 1
    description = "additive noise drawn uniformly with standard deviation s"

    @staticmethod
    def standard(key, shape, dtype):
        """Unit-variance uniform draws on (-sqrt 3, sqrt 3)."""
        return _random.uniform_law(key, shape, dtype)

    @classmethod
    def signature(cls, res):
        T = sum(np.sum(k, axis=1) for k in res.kurt_resid)
        return {"statistic": "excess kurtosis of the shots below the model's at equal size (uniform < 0)",
                "z": -res.over_inputs(T), "value": float(np.mean(T))}
