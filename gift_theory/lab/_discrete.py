"""Near-discrete data: a layer whose values sit on a lattice (a quantizing readout) is a finding.

A quantized readout (reference §2 ``quantization``) whose step is coarse against the noise gives
cells whose r shots are all identical: a within-cell variance of 0, which the identification
once divided by (a weight of 1 / 1e-300, an overflow, a singular normal matrix: ``gift
diagnose`` exited 1 on such a file). Here:

* :func:`resolution_var` -- the smallest variance a layer's cell can be read with: the rounding's
  variance step^2 / 12 on a lattice (Sheppard's correction for grouped data), else the float32
  resolution of its values; the identification reads every cell's variance at least at it;
* :func:`lattice_row` -- the identification's test of class ``readout_nonlinearity``: values on
  a lattice are what no continuous noise gives (ties have probability 0), and where the
  rounding's variance is not negligible against the layer's noise the class is named.
"""

from __future__ import annotations

import hashlib

import numpy as np
from scipy import stats

from ..effects.quantization import lattice_step

#: a layer's values within this fraction of a step of the lattice (:func:`lattice_step`'s tolerance)
TOLERANCE = 1e-3


_STEPS: dict = {}


def _step(Y):
    """:func:`lattice_step` of one layer's array, kept for the arrays seen last (the identification
    builds its layers several times over the same measurement). Keyed by the array's content: an
    id or an address is reused by the next array of that shape (a stale step, found in tests)."""
    Y = np.ascontiguousarray(Y)
    key = (Y.shape, Y.dtype.str, hashlib.blake2b(Y.view(np.uint8), digest_size=16).digest())
    if key not in _STEPS:
        if len(_STEPS) > 16:
            _STEPS.clear()
        _STEPS[key] = lattice_step([Y])
    return _STEPS[key]


def resolution_var(Y) -> float:
    """The variance below which a cell of layer values Y (n, r, d) is not resolved: step^2 / 12
    on a lattice, else (float32 eps x rms of Y)^2; > 0 unless Y is all zeros."""
    step = _step(Y)
    Y = np.asarray(Y, np.float64)
    rms = float(np.sqrt(np.mean(Y * Y)))
    floor = (float(np.finfo(np.float32).eps) * rms) ** 2
    return max(floor, (step * step / 12.0) if step else 0.0, np.finfo(np.float64).tiny)


def _z_of_log_p(log_p: float) -> float:
    """The normal z of a p-value given by its natural log (also where p underflows)."""
    if log_p > np.log(1e-300):
        return float(stats.norm.isf(np.exp(log_p)))
    L = -log_p  # the normal tail's asymptote: log p ~ -z^2 / 2 - log(z sqrt(2 pi))
    z = np.sqrt(2.0 * L)
    for _ in range(4):
        z = np.sqrt(max(2.0 * (L - np.log(z * np.sqrt(2.0 * np.pi))), 1e-12))
    return float(z)


def lattice_row(Y, layer: int) -> dict | None:
    """The lattice test of layer ``layer``'s values Y (n, r, d), or None when they are not on one.

    p bounds the chance that continuous noise puts all N values within :data:`TOLERANCE` of a
    step's multiple, (2 TOLERANCE)^N; the class is named (that p, else p = 1) when the rounding's
    variance step^2 / 12 exceeds three standard errors of the layer's mean within-cell variance
    (a rounding that small is below what the shots can show)."""
    step = _step(Y)
    if step is None:
        return None
    Y = np.asarray(Y, np.float64)
    n, r, d = Y.shape
    cell = np.var(Y, axis=1, ddof=1) if r > 1 else np.zeros((n, d))
    se = float(np.std(cell, ddof=1) / np.sqrt(cell.size)) if cell.size > 1 else 0.0
    rounding = step * step / 12.0
    distinct = len(np.unique(np.round(Y / step)))
    coarse = rounding > 3.0 * se
    log_p = Y.size * np.log(2.0 * TOLERANCE) if coarse else 0.0
    p = float(np.exp(log_p)) if coarse else 1.0
    z = _z_of_log_p(log_p) if coarse else 0.0
    share = rounding / max(float(np.mean(cell)), np.finfo(np.float64).tiny)
    evidence = (f"the {Y.size} values of layer {layer} sit on a lattice of step {step:.4g} ({distinct} levels; "
                f"{np.mean(cell == 0):.0%} of the cells' {r} shots all identical): a quantizing readout, whose "
                f"rounding (variance step^2/12) is {share:.2g} of the cells' variance"
                + ("" if coarse else " -- below what the shots resolve, not named"))
    return {"class": "readout_nonlinearity", "test": "lattice", "p": min(max(p, 0.0), 1.0), "z": z,
            "effect": float(step), "evidence": evidence, "neurons": (), "layers": [int(layer)]}
