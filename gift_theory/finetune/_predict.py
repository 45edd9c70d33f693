"""Theorem 1's first-order prediction of the change of J_st along the GIFT direction, against the referee.

Theorem 1 (paper, thm:main) rests on the first-order expansion along a unit direction u,

    dJ_st(a) = J_st(w0 + a u) - J_st(w0) ~ a <grad J_st(w0), u>,

and GIFT chooses u from d/ds grad J_s0(w0). For one fine-tuning run this module records

* the prediction ``a <grad J_st(w0), u>`` with <grad J_st(w0), u> estimated in silico
  (forward-mode derivative of the model's loss along u, the GIFT model family AWGN at the
  chip's noise level, K2 draws per training input; standard error over inputs), and the
  second-order one ``a <grad J_st, u> + a^2 u^T H_s0 u / 2`` with the line search's in-silico
  curvature at s0;
* the slope at s0, <grad J_s0(w0), u>: Theorem 1 assumes w0 critical at s0, so it should be 0
  within its error (a hypothesis check, not a prediction);
* the realised change J_st(w0 + a u) - J_st(w0) by the referee (true physics, paired over
  the same inputs and draws; standard error of the paired mean).

``a`` is the step of the line search's best measured point (``alpha_best``), whether or not the
confirmation accepted it, so every run with a line search gives a comparison.
"""

from __future__ import annotations

import math

import numpy as np

from .._model import named_subkey
from .._objective import directional_derivative, estimate_from_samples
from ..effects import awgn
from ._tree import axpy, unit


def candidate(w0, direction, step: float):
    """The weights w0 + a u, u the unit direction."""
    u, _ = unit(direction)
    return axpy(float(step), u, w0), u


def first_order_prediction(problem, u, step: float, s_model: float, curvature: float | None, *, K2: int = 8) -> dict:
    """Predicted change of J_st at ``w0 + step u`` (unit ``u``) from in-silico slopes at s0 and ``s_model``.

    Returns
    -------
    dict with ``step``, ``slope_st``, ``slope_st_se``, ``slope_s0``, ``slope_s0_se``,
    ``predicted_change`` (= step slope_st), ``predicted_change_se``, ``predicted_change_2nd``
    (adds step^2 curvature / 2; NaN without a curvature) and ``s_model``.
    """
    key = named_subkey(problem.key, "first_order_prediction")  # same draws at s0 and s_model
    slope = {}
    for name, s in (("st", s_model), ("s0", problem.s0)):
        slope[name] = problem.insilico(f"slope_{name}", (u, float(s), int(K2), key), lambda s=s: _slope(problem, key, u, s, K2))
    a = float(step)
    pred = a * slope["st"][0]
    return {"step": a, "s_model": float(s_model), "slope_st": slope["st"][0], "slope_st_se": slope["st"][1],
            "slope_s0": slope["s0"][0], "slope_s0_se": slope["s0"][1], "predicted_change": pred,
            "predicted_change_se": abs(a) * slope["st"][1],
            "predicted_change_2nd": pred + 0.5 * a * a * curvature if curvature is not None else math.nan}


def _slope(problem, key, u, s: float, K2: int) -> tuple[float, float]:
    est = directional_derivative(key, problem.w0, u, problem.x, problem.y, awgn(float(s)), problem.arch, K2=K2)
    return float(est.mean), float(est.se)


def realised_change(losses_before, losses_candidate) -> dict:
    """J_st(candidate) - J_st(w0) from the referee's per-input losses on the same draws."""
    d = estimate_from_samples(np.asarray(losses_candidate, np.float64) - np.asarray(losses_before, np.float64))
    return {"realised_change": float(d.mean), "realised_change_se": float(d.se)}
