"""A teacher: inputs from a stated distribution labelled by a fixed random network.

Because samples are drawn fresh on demand, J_s can be estimated to any precision --
the theory checks need this (the data distribution mu of the paper is then known).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .. import _random
from .._arch import Architecture
from .._errors import require
from .._params import init_params
from ._types import Dataset


@dataclasses.dataclass(frozen=True)
class Teacher:
    """Inputs x ~ N(0, input_scale^2 I_{d_0}) (or uniform on [0, 1]^{d_0}); targets y = T(x).

    T is a noiseless network of architecture ``widths`` (activation ``activation``) with
    Glorot-uniform weights of gain ``gain`` drawn from ``seed``; biases are N(0, 0.1^2).

    Parameters
    ----------
    widths : (d_0, ..., d_L) of the teacher
    seed : int, names the teacher
    input_dist : "normal" or "uniform"
    """

    widths: tuple = (4, 8, 2)
    seed: int = 0
    activation: str = "tanh"
    input_dist: str = "normal"
    input_scale: float = 1.0
    gain: float = 1.5

    def __post_init__(self):
        require(self.input_dist in ("normal", "uniform"),
                f"teacher: input_dist must be normal or uniform, got {self.input_dist!r}")
        object.__setattr__(self, "widths", tuple(int(w) for w in self.widths))
        Architecture(self.widths, self.activation)  # validates

    @property
    def arch(self) -> Architecture:
        return Architecture(self.widths, self.activation)

    def params(self, dtype=jnp.float32):
        key = jax.random.PRNGKey(self.seed)
        p = init_params(key, self.arch, dtype=dtype, gain=self.gain)
        return tuple(type(layer)(layer.W, 0.1 * _random.normal_like_jax(jax.random.fold_in(key, 99 + l), layer.b.shape, dtype))
                     for l, layer in enumerate(p))

    def inputs(self, key, n: int, dtype=jnp.float32):
        if self.input_dist == "normal":
            return self.input_scale * _random.normal_like_jax(key, (n, self.widths[0]), dtype)
        return _random.uniform_like_jax(key, (n, self.widths[0]), dtype)

    def label(self, x):
        """The teacher's noiseless output T(x); x of shape (..., d_0)."""
        sigma = self.arch.sigma
        a = x
        p = self.params(x.dtype)
        for l, (W, b) in enumerate(p, start=1):
            z = a @ W.T + b
            a = sigma(z) if l < len(p) else z
        return a

    def sample(self, key, n: int, dtype=jnp.float32):
        """``(x, y)`` with x of shape (n, d_0) and y = T(x) of shape (n, d_L)."""
        x = self.inputs(key, n, dtype)
        return x, self.label(x)


def teacher_dataset(n_train: int = 2000, n_test: int = 1000, **teacher):
    """A fixed train/test draw from :class:`Teacher` as a :class:`Dataset` (labels: argmax)."""

    t = Teacher(**teacher)
    xtr, ytr = t.sample(jax.random.PRNGKey(10_000 + t.seed), n_train)
    xte, yte = t.sample(jax.random.PRNGKey(20_000 + t.seed), n_test)
    xtr, ytr, xte, yte = (np.asarray(a, np.float32) for a in (xtr, ytr, xte, yte))
    return Dataset("teacher", xtr, ytr, ytr.argmax(1), xte, yte, yte.argmax(1),
                   {"source": f"Teacher{dataclasses.asdict(t)}", "scaling": "none"})
