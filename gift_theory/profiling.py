"""Profiling hooks for the packages on top of gift (paper_figures' profiles): phase clocks with
JAX's compile time per phase and the host's matmul rate. Public re-exports of the core's own
tools."""

import time

import numpy as np

from ._phases import PhaseClock as PhaseClock
from ._phases import compile_totals as compile_totals
from ._phases import compiled_functions as compiled_functions
from ._phases import listen as listen
from ._phases import phase as phase


def matmul_gflops(n: int = 2048, repeats: int = 10) -> float:
    """The host's numpy float32 n x n matmul rate in GFLOP/s, best of ``repeats``."""
    a = np.random.default_rng(0).standard_normal((n, n)).astype(np.float32)
    b = np.random.default_rng(1).standard_normal((n, n)).astype(np.float32)
    a @ b
    best = min(_timed(lambda: a @ b) for _ in range(repeats))
    return 2.0 * n ** 3 / best / 1e9


def _timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t
