"""A simulated chip: the model M_s with hidden true physics (noise level st and any
CONTRACTS §2 effects). Fresh noise on every call -- a real device cannot repeat its noise,
so methods get no common random numbers across calls from it."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._arch import Architecture
from .._errors import require
from .._model import forward, sample_noise
from .._params import check_params
from ..effects import Physics
from ._base import Ledger, Measurement


@partial(jax.jit, static_argnames=("arch", "shots", "taps", "with_t"))
def _measure(key, params, x, physics, *, arch, shots, taps, with_t):
    dtype = params[0].W.dtype
    noise = sample_noise(key, arch, physics, (x.shape[0], shots), dtype)
    n = x.shape[0] * shots
    # drift: shots acquired one after the other over the call, t normalised to [0, 1]
    t = (jnp.arange(n, dtype=dtype) / max(n - 1, 1)).reshape(x.shape[0], shots) if with_t else None
    out = forward(params, x[:, None, :].astype(dtype), noise, physics, arch, t=t, taps=taps)
    return out.y, (out.taps[:-1] if taps else ()), t


class SimulatedChip:
    """The model with hidden true physics, behind the :class:`~gift_theory.chips.Chip` protocol.

    Parameters
    ----------
    arch : Architecture
    physics : Physics, the device's true effects (e.g. ``Physics.create(s=0.2, shot=0.01)``)
    key : PRNG key of the device's noise; call ``c`` uses ``fold_in(key, c)``
    budget_shots : optional shot budget (see :class:`Ledger`)
    """

    def __init__(self, arch: Architecture, physics: Physics, key=None, budget_shots: int | None = None):
        self.arch = arch
        self.widths = arch.widths
        self.physics = physics
        self.key = jax.random.PRNGKey(0) if key is None else key
        self.ledger = Ledger(budget_shots)
        self._calls = 0

    def measure(self, params, x, shots: int, *, taps: bool = False, key=None) -> Measurement:
        """Send each row of ``x`` (n, d_0) ``shots`` times through the device with ``params``.

        Returns a :class:`Measurement` with ``y`` of shape (n, shots, d_L). Charges
        ``n * shots`` shots to the ledger first (raises BudgetExceeded without measuring).
        """
        params = check_params(params, self.arch, "chip weights")
        x = np.asarray(x)
        require(x.ndim == 2 and x.shape[1] == self.widths[0],
                f"chip: inputs have shape {x.shape}, the chip takes (n, {self.widths[0]})")
        shots = int(shots)
        require(shots >= 1, f"chip: shots must be at least 1, got {shots}")
        self.ledger.charge(x.shape[0] * shots)
        k = jax.random.fold_in(self.key, self._calls) if key is None else key
        self._calls += 1
        y, tp, t = _measure(k, params, jnp.asarray(x), self.physics, arch=self.arch, shots=shots, taps=bool(taps),
                            with_t="drift" in self.physics)
        return Measurement(x, np.asarray(y), tuple(np.asarray(a) for a in tp), None if t is None else np.asarray(t))

    def __repr__(self):
        return f"SimulatedChip({self.arch}, hidden physics, {self.ledger.shots} shots used)"
