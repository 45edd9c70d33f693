"""The compact tanh ONN shared by the numerical checks: teacher data, w0 trained at s0, and
the Theorem-1 quantities at (s0, st); built once per process."""

from __future__ import annotations

from typing import NamedTuple

import jax

import gift_theory as gt

from . import _mc
from ._theorem1 import theorem1_check

_CACHE: dict = {}


class Setup(NamedTuple):
    problem: _mc.Problem
    w0: tuple
    s0: float
    st: float
    theorem1: dict


def setup(precise: bool = False, s0: float = 0.1, st: float = 0.3) -> Setup:
    """Arch 3-4-2 tanh, 256 teacher points (the data measure mu), w0 ~ critical point of J_s0."""
    k = (precise, s0, st)
    if k not in _CACHE:
        with jax.enable_x64(True):
            arch = gt.Architecture((3, 4, 2))
            prob = _mc.teacher_problem(jax.random.PRNGKey(11), arch, n=256, s=s0)
            w0 = _mc.train_critical(jax.random.PRNGKey(12), prob, s0, K2=64 if precise else 32,
                                    steps=3000 if precise else 1500)
            th1 = theorem1_check(jax.random.PRNGKey(13), w0, prob.x, prob.y, prob.physics, arch, s0, st,
                                 K2=32 if precise else 16, n_zeta=5 if precise else 3)
        _CACHE[k] = Setup(prob, w0, s0, st, th1)
    return _CACHE[k]
