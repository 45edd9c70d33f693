"""The Chip protocol: what a fine-tuning method may ask of a device, and the shot ledger.

A chip takes programmed weights, a batch of inputs and a number of shots and returns the
measured outputs (and the hidden-layer taps where it has them). Every call is counted in
shots against a budget the caller sets; fine-tuning methods report their chip use in
units of one Eval_w(K1, K2) (eq. def:Eval), i.e. ``ceil(shots / (K1 K2))``.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from .._errors import GiftInputError
from .._measurement import Measurement


class BudgetExceeded(RuntimeError):
    """A chip call would use more shots than the budget allows (the call is not made)."""


@runtime_checkable
class Chip(Protocol):
    """A device that runs an ONN forward: weights in, measured outputs out.

    Attributes
    ----------
    widths : tuple of int, the architecture the chip implements (d_0, ..., d_L)
    ledger : :class:`Ledger`, the shots used and the budget
    """

    widths: tuple
    ledger: "Ledger"

    def measure(self, params, x, shots: int, *, taps: bool = False, key=None) -> Measurement:
        """Program ``params``, send each row of ``x`` (n, d_0) ``shots`` times, return the
        :class:`~gift_theory.Measurement` (reference §3: the inputs, the shots, the programmed
        weights, the hidden layers' taps when asked and the chip has them, else None)."""
        ...


class Ledger:
    """Counts shots (one shot = one input sent once) against an optional budget.

    A device is a stateful thing, so this is the one mutable object of the design; every
    :class:`Chip` owns one and charges it *before* it measures.
    """

    def __init__(self, budget_shots: int | None = None):
        self.budget_shots = None if budget_shots is None else int(budget_shots)
        self.shots = 0
        self.calls = 0

    def charge(self, n_shots: int) -> None:
        n_shots = int(n_shots)
        if n_shots < 0:
            raise GiftInputError(f"chip: negative number of shots {n_shots}")
        if self.budget_shots is not None and self.shots + n_shots > self.budget_shots:
            raise BudgetExceeded(f"chip budget: {self.shots} + {n_shots} shots > {self.budget_shots}")
        self.shots += n_shots
        self.calls += 1

    def remaining(self) -> float:
        return math.inf if self.budget_shots is None else self.budget_shots - self.shots

    def evaluations(self, K1: int, K2: int) -> int:
        """Chip use in units of one Eval_w(K1, K2): ``ceil(shots / (K1 K2))``."""
        return int(math.ceil(self.shots / (int(K1) * int(K2))))

    def set_budget_evaluations(self, evaluations: float, K1: int, K2: int) -> None:
        """Allow ``evaluations`` Eval_w(K1, K2) from now on (counting what is already used)."""
        self.budget_shots = self.shots + int(round(evaluations * K1 * K2))


def chip_eval(chip: Chip, params, x, y, K2: int):
    """Eval_w(K1, K2) measured on ``chip`` (eq. def:Eval): per-input mean squared errors.

    Parameters
    ----------
    chip : Chip
    x : (K1, d_0), y : (K1, d_L)
    K2 : shots per input

    Returns
    -------
    ndarray (K1,) of per-input means over the K2 shots of (y - output)^2 summed over outputs;
    their mean is Eval and their standard deviation / sqrt(K1) its standard error.
    """
    m = chip.measure(params, x, K2)
    out = np.asarray(m.y, dtype=np.float64)
    return np.sum((out - np.asarray(y, np.float64)[:, None, :]) ** 2, axis=-1).mean(axis=1)
