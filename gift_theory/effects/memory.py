"""``memory``: each layer output fed forward, and the readout, adds alpha times the same neuron's
value of the shot acquired just before, in acquisition-time order (reference §8; §6 class
``memory``: detector bandwidth, thermal memory). It needs the acquisition times t.

The last link of the readout chain D: ``out_k = D(v_k) + alpha out_{k-1}``, k the shot's rank
in t over the whole campaign (every input's shots), ``out`` of the first shot its own value.
The previous shot's value is its output -- memory included -- so the response to one shot
decays as alpha^j over the next j shots (a first-order detector).

A model's shots repeat the measured times (K shots per input are the measured r tiled, two
copies of the campaign in a chunk of 2 r): shots with equal times are copies of one acquisition,
and the c-th copy of a time follows the c-th copy of the time before (each copy a campaign of
its own). The recurrence is solved by pointer doubling: log2 of the shots' number of gathers,
differentiable in alpha.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._base import Effect, register


def previous_shot(t):
    """For flat acquisition times ``t`` (N,): the flat index of the shot acquired just before each
    one in the same copy of the campaign (see the module), -1 for a first shot."""
    N = t.shape[0]
    order = jnp.argsort(t, stable=True)
    ts = t[order]
    pos = jnp.arange(N)
    new = jnp.concatenate([jnp.ones((1,), bool), ts[1:] != ts[:-1]])
    start = lax.cummax(jnp.where(new, pos, 0), axis=0)  # first sorted position of a shot's time
    copy = pos - start
    prev_end = start - 1  # the last sorted position of the time before (-1: none)
    prev_start = start[jnp.maximum(prev_end, 0)]
    pred = jnp.where(prev_end >= 0, prev_start + jnp.minimum(copy, prev_end - prev_start), -1)
    flat = jnp.where(pred >= 0, order[jnp.maximum(pred, 0)], -1)
    return jnp.full((N,), -1, flat.dtype).at[order].set(flat)


def with_memory(v, t, alpha):
    """``out_k = v_k + alpha out_{k-1}`` along acquisition order; v (..., d), t broadcastable to
    v's batch axes (..., 1) or (...)."""
    batch = v.shape[:-1]
    tt = jnp.broadcast_to(jnp.asarray(t).reshape(jnp.asarray(t).shape[:len(batch)]), batch).reshape(-1)
    y = v.reshape(-1, v.shape[-1])
    P = previous_shot(tt)
    mult = alpha
    for _ in range(max(1, math.ceil(math.log2(max(tt.shape[0], 2))))):
        y = y + mult * jnp.where((P >= 0)[:, None], y[jnp.maximum(P, 0)], 0.0)
        P = jnp.where(P >= 0, P[jnp.maximum(P, 0)], -1)
        mult = mult * mult
    return y.reshape(v.shape)


@register
class Memory(Effect):
    alpha: float | jax.Array = 0.1

    name = "memory"
    params = ("alpha",)
    bounds = {"alpha": (-0.95, 0.95)}
    defaults = {"alpha": 0.1}
    stage = "readout"
    mechanism = "memory"
    # the last link of D: what is measured (and fed forward) carries the previous shot's output
    order = 9
    description = "each output adds alpha times the same neuron's output of the shot acquired before it"

    def readout(self, v, noise, layer, t):
        return with_memory(v, t, self.alpha)

    @classmethod
    def search(cls, param, layers):
        return np.linspace(-0.6, 0.6, 25)
