"""ONN parameters ``w = ((W_1, b_1), ..., (W_L, b_L))`` as a pytree, and the box H.

Paper, Sections "Modeling ONNs" and "Modeling physical limitations"
(eq. ass:H-is-a-hyperrectangle).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from . import _random
from ._arch import Architecture
from ._errors import GiftInputError, require


class Layer(NamedTuple):
    """One layer: ``W`` of shape (d_l, d_{l-1}) and ``b`` of shape (d_l,)."""

    W: jax.Array
    b: jax.Array


Params = tuple  # tuple[Layer, ...]


class Box(NamedTuple):
    """The feasible hyperrectangle H: ``W_min <= W_ij <= W_max``, ``b_min <= b_i <= b_max``."""

    W_min: float = -1.0
    W_max: float = 1.0
    b_min: float = -1.0
    b_max: float = 1.0


def init_params(key: jax.Array, arch: Architecture, *, dtype=jnp.float32, gain: float = 1.0) -> Params:
    """Glorot-style initial weights, zero biases.

    Parameters
    ----------
    key : PRNG key
    arch : Architecture
    dtype : float32 (default) or float64
    gain : scale of the uniform range ``gain * sqrt(6 / (fan_in + fan_out))``.
    """
    layers = []
    for l, (d_in, d_out) in enumerate(zip(arch.widths[:-1], arch.widths[1:])):
        k = jax.random.fold_in(key, l)
        lim = gain * np.sqrt(6.0 / (d_in + d_out))
        W = _random.uniform_like_jax(k, (d_out, d_in), dtype, -lim, lim)  # jax.random.uniform's numbers
        layers.append(Layer(W, jnp.zeros((d_out,), dtype)))
    return tuple(layers)


def to32(a):
    """``a`` as a float32 device array, converted on the host (the same rounding): an eager
    ``jnp.asarray(a, jnp.float32)`` of a float64 array compiles a conversion program per shape."""
    if isinstance(a, jax.Array):
        return a if a.dtype == jnp.float32 else a.astype(jnp.float32)
    return jax.device_put(np.asarray(a, np.float32))


def params32(params):
    """Weights as float32 :class:`Layer` s (what the simulated chip and every jitted pass of the lab take)."""
    return tuple(Layer(to32(W), to32(b)) for W, b in params)


def check_params(params: Sequence, arch: Architecture, where: str = "weights") -> Params:
    """Validate shapes against ``arch``; return ``params`` as a tuple of :class:`Layer`.

    Raises :class:`GiftInputError` with one line naming the first mismatch.
    """
    require(len(params) == arch.depth,
            f"{where}: {len(params)} layers given, architecture {arch} has {arch.depth}")
    out = []
    for l, layer in enumerate(params, start=1):
        try:
            W, b = layer
        except (TypeError, ValueError):
            raise GiftInputError(f"{where}: layer {l} is not a (W, b) pair") from None
        want_W = (arch.widths[l], arch.widths[l - 1])
        require(tuple(np.shape(W)) == want_W,
                f"{where}: W{l} has shape {tuple(np.shape(W))}, architecture {arch} needs {want_W}")
        require(tuple(np.shape(b)) == (arch.widths[l],),
                f"{where}: b{l} has shape {tuple(np.shape(b))}, architecture {arch} needs {(arch.widths[l],)}")
        require(bool(np.all(np.isfinite(np.asarray(W)))) and bool(np.all(np.isfinite(np.asarray(b)))),
                f"{where}: layer {l} contains NaN or Inf")
        out.append(Layer(jnp.asarray(W), jnp.asarray(b)))
    return tuple(out)


def arch_of(params: Sequence, activation: str = "tanh", noise_sites: str = "all") -> Architecture:
    """The architecture whose widths match ``params``."""
    widths = [int(np.shape(params[0][0])[1])] + [int(np.shape(W)[0]) for W, _ in params]
    return Architecture(tuple(widths), activation, noise_sites)


def project(params: Params, box: Box) -> Params:
    """The Euclidean projection p_H onto the box H (eq. projected-sgd)."""
    return tuple(Layer(jnp.clip(W, box.W_min, box.W_max), jnp.clip(b, box.b_min, box.b_max)) for W, b in params)


def flatten(params: Params):
    """``(vector, unflatten)`` -- the parameters as one vector and the inverse map."""
    return ravel_pytree(params)


def params_to_arrays(params: Params) -> dict[str, np.ndarray]:
    """``{"W1": ..., "b1": ..., ...}`` as in measurement and weight files (reference §3)."""
    out = {}
    for l, (W, b) in enumerate(params, start=1):
        out[f"W{l}"] = np.asarray(W)
        out[f"b{l}"] = np.asarray(b)
    return out


def params_from_arrays(arrays, where: str = "file") -> Params:
    """Inverse of :func:`params_to_arrays`; layers are read while ``W{l}`` exists."""
    layers = []
    l = 1
    keys = set(arrays.keys()) if hasattr(arrays, "keys") else set(arrays)
    while f"W{l}" in keys:
        require(f"b{l}" in keys, f"{where}: has W{l} but no b{l}")
        layers.append(Layer(jnp.asarray(np.asarray(arrays[f"W{l}"], dtype=np.float64)),
                            jnp.asarray(np.asarray(arrays[f"b{l}"], dtype=np.float64))))
        l += 1
    require(layers, f"{where}: no weights (expected keys W1, b1, ...)")
    for l in range(1, len(layers)):
        require(layers[l].W.ndim == 2 and layers[l - 1].W.ndim == 2 and layers[l].W.shape[1] == layers[l - 1].W.shape[0],
                f"{where}: W{l + 1} has shape {tuple(layers[l].W.shape)}, which does not follow W{l} of shape "
                f"{tuple(layers[l - 1].W.shape)}")
    return tuple(layers)


def cast(params: Params, dtype) -> Params:
    return jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), params)
