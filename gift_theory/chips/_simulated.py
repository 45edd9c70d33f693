"""A simulated chip: the model M_s with hidden true physics (noise level st and any
reference §2 effects). Each campaign's noise is drawn from the chip's key and what the campaign
asks (weights, inputs, shots, taps, times): different campaigns get independent noise, the same
campaign the same noise, whatever was measured before it (same seed, same numbers, in any order)."""

from __future__ import annotations

import hashlib
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._arch import Architecture
from .._errors import require
from .._finite import check_all_finite
from .._model import compiled_draws, forward
from .._params import Layer, check_params, params32
from ..effects import Physics
from .._measurement import Measurement
from ._base import Ledger


def _measure(key, params, x, physics, *, arch, shots, taps, with_t):
    """A campaign's shots: its draws by the programs of their padded lengths
    (:func:`~gift_theory._model.compiled_draws`), then the forward pass, so a new campaign shape
    or physics compiles only the forward pass."""
    noise = compiled_draws(key, physics, arch=arch, shape=(x.shape[0], shots), dtype=params[0].W.dtype)
    return _measure_forward(params, x, noise, physics, arch=arch, shots=shots, taps=taps, with_t=with_t)


@partial(jax.jit, static_argnames=("arch", "shots", "taps", "with_t"))
def _measure_forward(params, x, noise, physics, *, arch, shots, taps, with_t):
    dtype = params[0].W.dtype
    n = x.shape[0] * shots
    # drift: shots acquired one after the other over the call, t normalised to [0, 1]
    t = (jnp.arange(n, dtype=dtype) / max(n - 1, 1)).reshape(x.shape[0], shots) if with_t else None
    out = forward(params, x[:, None, :].astype(dtype), noise, physics, arch, t=t, taps=taps)
    return out.y, (out.taps[:-1] if taps else ()), t


def campaign_key(key, params, x, shots: int, taps: bool, times: bool):
    """``key`` folded with a digest of a campaign (the weights, the inputs, the shots, whether it
    records taps and times): the noise of a campaign depends on what it asks, never on the order
    campaigns are run in."""
    h = hashlib.sha256()
    for W, b in params:
        h.update(np.ascontiguousarray(np.asarray(W, np.float64)).tobytes())
        h.update(np.ascontiguousarray(np.asarray(b, np.float64)).tobytes())
    h.update(np.ascontiguousarray(np.asarray(x, np.float64)).tobytes())
    h.update(f"{np.shape(x)}/{int(shots)}/{bool(taps)}/{bool(times)}".encode())
    return jax.random.fold_in(key, int.from_bytes(h.digest()[:4], "little") & 0x7FFFFFFF)


class SimulatedChip:
    """The model with hidden true physics, behind the :class:`~gift_theory.chips.Chip` protocol.

    Parameters
    ----------
    arch : Architecture
    physics : Physics, the device's true effects (e.g. ``Physics.create(s=0.2, shot=0.01)``)
    key : PRNG key of the device's noise; a campaign uses it folded with a digest of what it asks
        (:func:`campaign_key`), unless :meth:`measure` is given a key of its own
    budget_shots : optional shot budget (see :class:`Ledger`)
    """

    def __init__(self, arch: Architecture, physics: Physics, key=None, budget_shots: int | None = None):
        physics.check_scope(arch, "chip physics")
        self.arch = arch
        self.widths = arch.widths
        self.physics = physics
        self.key = jax.random.PRNGKey(0) if key is None else key
        self.ledger = Ledger(budget_shots)

    def measure(self, params, x, shots: int, *, taps: bool = False, key=None, times: bool | None = None) -> Measurement:
        """Send each row of ``x`` (n, d_0) ``shots`` times through the device with ``params``.

        Returns a :class:`~gift_theory.Measurement` with ``y`` of shape (n, shots, d_L), the
        programmed weights (float64) and, with ``taps``, the hidden layers. The shots are
        acquired input by input, shot by shot: t = (i shots + j) / (n shots - 1), recorded when
        ``times`` is true (default: when an effect of the device acts through them -- drift, memory: ``needs_times``;
        ``times=False`` then is a bad input). Charges ``n * shots`` shots to the
        ledger first (raises BudgetExceeded without measuring). ``key``: the campaign's noise
        (default :func:`campaign_key`: the same campaign, the same shots).
        """
        params = check_params(params, self.arch, "chip weights")
        x = np.asarray(x)
        require(x.ndim == 2 and x.shape[1] == self.widths[0],
                f"chip: inputs have shape {x.shape}, the chip takes (n, {self.widths[0]})")
        shots = int(shots)
        require(shots >= 1, f"chip: shots must be at least 1, got {shots}")
        self.ledger.charge(x.shape[0] * shots)
        need = self.physics.needs_times()
        require(times is None or times or not need, f"chip: effect {', '.join(need)} acts through the acquisition "
                                                   f"times t; a campaign without times cannot run it")
        with_t = bool(need) if times is None else bool(times)
        tapped = bool(taps) and self.arch.depth > 1
        k = campaign_key(self.key, params, x, shots, tapped, with_t) if key is None else key
        y, tp, t = _measure(k, params, jnp.asarray(x), self.physics, arch=self.arch, shots=shots,
                            taps=tapped, with_t=with_t)

        def rerun(j, at):  # the campaign again, eagerly: a plugin hook that made the bad value is named
            with jax.disable_jit():
                _measure(k, params, jnp.asarray(x), self.physics, arch=self.arch, shots=shots, taps=tapped,
                         with_t=with_t)
        check_all_finite(tuple(tp) + (y,), [f"the simulated shots of layer {l} ({self.physics.describe()})"
                                            for l in (range(1, self.arch.depth + 1) if tapped
                                                      else (self.arch.depth,))], rerun)
        programmed = tuple(Layer(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in params)
        return Measurement(np.asarray(x, np.float64), np.asarray(y, np.float64), programmed,
                           tuple(np.asarray(a, np.float64) for a in tp) if taps and self.arch.depth > 1 else None,
                           None if t is None else np.asarray(t, np.float64), self.arch.activation)

    def __repr__(self):
        return f"SimulatedChip({self.arch}, hidden physics, {self.ledger.shots} shots used)"


def simulate_measurement(key, params, x, physics: Physics, *, shots: int, activation: str = "tanh",
                         taps: bool = False, times: bool = False) -> Measurement:
    """A measurement campaign on a :class:`SimulatedChip` (the hidden-effect data generator).

    Parameters
    ----------
    key : PRNG key of the device's noise for this campaign
    params : tuple of Layer, the programmed weights
    x : (n, d_0)
    physics : Physics of the simulated device (its hidden effects)
    shots : r, repeated shots per input
    taps : record the hidden layers a_1..a_{L-1}
    times : record acquisition times t (the campaign runs input by input, shot by shot;
        drift is silent without times)

    Returns
    -------
    Measurement
    """
    widths = (int(params[0][0].shape[1]),) + tuple(int(W.shape[0]) for W, _ in params)
    chip = SimulatedChip(Architecture(widths, activation), physics, key)
    p32 = params32(params)
    return chip.measure(p32, np.asarray(x, np.float64), int(shots), taps=taps, key=key, times=True if times else None)
