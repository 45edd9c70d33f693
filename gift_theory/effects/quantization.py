"""``quantization``: the readout maps v to clip(round(v / step) step, -v_range, v_range),
step = 2 v_range / 2^bits (last link of D).

The rounding's derivative is zero almost everywhere, so a model with this effect had no
gradient at all (D follows every layer): training, GIFT's directions and the offset fits
under it returned their start unchanged. Its derivative is the straight-through one, 1 (the
forward is unchanged, bit for bit): the derivative of the *expected* readout
E[round((v + n) / step)] step under the noise n that precedes D, which tends to 1 as the step
shrinks against the noise's spread (at step = the noise's standard deviation it is already
within 1e-8 of 1 for Gaussian n, by the Poisson summation formula).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, register


@jax.custom_jvp
def round_straight_through(x):
    """``jnp.round(x)`` whose derivative is 1 (the straight-through estimator)."""
    return jnp.round(x)


@round_straight_through.defjvp
def _round_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return jnp.round(x), t


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
        return jnp.clip(round_straight_through(v / step) * step, -self.v_range, self.v_range)

    @classmethod
    def from_data(cls, layers):
        """``bits`` and ``v_range`` read off the lattice the measured values sit on (None when they
        do not): ``bits`` is the smallest integer with ``step 2^(bits-1)`` at least the largest
        measured magnitude, ``v_range = step 2^(bits-1)``; without a lattice, 16 bits over the
        measured range."""
        step = lattice_step(layers)
        vmax = max(float(np.max(np.abs(a))) for a in layers)
        if step is None:
            return {"bits": 16.0, "v_range": vmax}
        bits = min(max(1, int(np.ceil(np.log2(max(vmax / step, 1.0) - 1e-6))) + 1), 32)
        return {"bits": float(bits), "v_range": float(step * 2.0 ** (bits - 1))}

    @classmethod
    def signature(cls, res):
        step = lattice_step(res.Y)
        return {"statistic": (f"measured values sit on a lattice of step {step:.4g}" if step else
                              "measured values are not on a lattice"),
                "value": float(step) if step else float("nan"), "z": float("nan"), "stands_out": step is not None}


def lattice_step(layers):
    """The spacing of the lattice the measured values (a list of arrays) sit on, or None.

    The candidate step is the smallest clear gap between distinct measured values; the
    values are on the lattice when every one is within 1e-3 step of a multiple of it.
    """
    total, u = sum(np.size(a) for a in layers), np.empty(0)
    for a in sorted(layers, key=np.size, reverse=True):  # a layer at a time: a continuous file stops early
        v = np.round(np.ravel(a), 9)  # ours: sorted and thinned in place (np.unique's numbers, one copy)
        v.sort()
        keep = np.empty(v.size, bool)
        keep[:1] = True
        np.not_equal(v[1:], v[:-1], out=keep[1:])
        u = np.union1d(u, v[keep]) if u.size else v[keep]
        del v, keep
        if len(u) > 0.5 * total:
            return None
    if len(u) < 2:
        return None
    gaps = np.diff(u)
    scale = max(np.max(np.abs(u)), 1e-12)
    gaps = gaps[gaps > 1e-7 * scale]
    if len(gaps) == 0:
        return None
    step = float(np.min(gaps))
    # refine with the median of gaps that are one step wide
    one = gaps[np.abs(gaps / step - 1.0) < 0.01]
    step = float(np.median(one)) if len(one) else step
    resid = np.abs(u / step - np.round(u / step))
    if np.max(resid) > 1e-3:
        return None
    return step
