"""One fine-tuning problem: trained weights w0, a chip with hidden physics, a budget, a referee.

The referee is the simulator's truth (the true physics, many draws, common random numbers
across methods); it is how results are scored and is never charged to the chip budget.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._arch import Architecture
from .._memo import digest, lookup, memoized, store
from .._objective import estimate_from_samples, per_input_loss, per_input_scores
from .._params import cast
from .._phases import phase
from ..chips import SimulatedChip, chip_eval
from ..effects import Physics, awgn


class Problem(NamedTuple):
    """Everything a fine-tuning method may use.

    arch, s0 : the architecture and the assumed noise level of the model
    model : Physics of the model (awgn(s0)); chip : the device (its physics is hidden)
    w0 : weights trained in silico at s0
    x, y : (n, d_0), (n, d_L) training data (in silico use is free)
    x_ft, y_ft : (K1, d_0), (K1, d_L) the fine-tuning set; K2 shots per input per Eval
    budget : chip evaluations allowed, in units of Eval_w(K1, K2)
    key : PRNG key for the method's own randomness
    """

    arch: Architecture
    s0: float
    model: Physics
    chip: object
    w0: tuple
    x: jax.Array
    y: jax.Array
    x_ft: np.ndarray
    y_ft: np.ndarray
    K2: int
    budget: float
    key: jax.Array

    @property
    def K1(self) -> int:
        return int(self.x_ft.shape[0])

    @property
    def unit_shots(self) -> int:
        return self.K1 * self.K2

    def eval_chip(self, params) -> np.ndarray:
        """Per-input losses of one Eval_w(K1, K2) on the chip (charged: one unit)."""
        with phase("chip"):
            return chip_eval(self.chip, params, self.x_ft, self.y_ft, self.K2)

    def evaluations_left(self) -> float:
        return self.chip.ledger.remaining() / self.unit_shots

    def evaluations_used(self) -> int:
        return self.chip.ledger.evaluations(self.K1, self.K2)

    def insilico(self, tag: str, parts, compute):
        """``compute()`` memoized on everything an in-silico result of this problem can depend on
        (the model, w0, the training data, the fine-tuning set, K2 and the key; never the chip)
        plus ``parts``: runs that differ only in their chip share it (:mod:`gift_theory._memo`)."""
        return memoized(tag, (self.arch, self.s0, self.model, self.w0, self.x, self.y, self.x_ft, self.y_ft,
                              self.K2, self.key, parts), compute)


def make_problem(arch: Architecture, w0, x, y, *, s0: float, true_physics: Physics, budget: float = 20, K1=None,
                 K2: int = 1, seed: int = 0, chip=None) -> Problem:
    """Build a problem; the fine-tuning set is the first ``K1`` training inputs (all by default).

    A ``chip`` may be given (anything with the Chip protocol); otherwise a
    :class:`~gift_theory.chips.SimulatedChip` with ``true_physics`` is made, its noise
    named by ``seed``.
    """
    w0 = cast(w0, jnp.float32)
    x = jnp.asarray(x, jnp.float32)
    y = jnp.asarray(y, jnp.float32)
    K1 = x.shape[0] if K1 is None else min(int(K1), x.shape[0])
    key = jax.random.PRNGKey(seed)
    if chip is None:
        chip = SimulatedChip(arch, true_physics, key=jax.random.fold_in(key, 7))
    chip.ledger.set_budget_evaluations(budget, K1, K2)
    return Problem(arch, float(s0), awgn(s0), chip, w0, x, y, np.asarray(x[:K1]), np.asarray(y[:K1]), int(K2),
                   float(budget), jax.random.fold_in(key, 11))


def referee_scores(weight_sets, x, y, labels, physics: Physics, arch: Architecture, *, K2: int = 32,
                   seed: int = 12345):
    """Per-input true losses and correctness, (P, K1) each, of P weight sets on the same draws.

    One pass over the inputs scores every weight set (common random numbers) and gives loss
    and accuracy from the same noisy outputs; the draws are those of :func:`referee_losses`.
    A weight set is scored once however often it is listed (a method that returns w0 costs no
    second pass), and the first set's scores are memoized (:mod:`gift_theory._memo`): every
    method run on the same w0 and chip physics scores its "before" once. A set's scores do not
    depend on the other sets of the pass (the pass is vmapped over sets), so the numbers are
    those of one pass over all of them.
    """
    sets = [cast(p, jnp.float32) for p in weight_sets]
    ids = [digest(p) for p in sets]
    unique = list(dict.fromkeys(ids))
    first_parts = (ids[0], x, y, labels, physics, arch, int(K2), int(seed))
    known = {}
    first = lookup("referee_first", first_parts)
    if first is not None:
        known[ids[0]] = first
    todo = [i for i in unique if i not in known]
    if todo:
        t0 = time.perf_counter()
        losses, correct = per_input_scores(jax.random.PRNGKey(seed), [sets[ids.index(i)] for i in todo], x, y,
                                           labels, physics, arch, K2)
        for j, i in enumerate(todo):
            known[i] = (None if losses is None else losses[j], None if correct is None else correct[j])
        if ids[0] in todo:
            store("referee_first", first_parts, known[ids[0]], time.perf_counter() - t0)
    rows = [known[i] for i in ids]
    losses = None if rows[0][0] is None else np.stack([np.asarray(r[0]) for r in rows])
    correct = None if rows[0][1] is None else np.stack([np.asarray(r[1]) for r in rows])
    return losses, correct


def summary(losses, correct) -> dict:
    """Referee numbers of one weight set from its per-input losses and correctness."""
    j, a = estimate_from_samples(losses), estimate_from_samples(correct)
    return {"loss": float(j.mean), "loss_se": float(j.se), "accuracy": float(a.mean), "accuracy_se": float(a.se)}


def referee(params, x, y, labels, physics: Physics, arch: Architecture, *, K2: int = 32, seed: int = 12345) -> dict:
    """True loss and accuracy under ``physics`` (many draws, fixed key: common random numbers)."""
    losses, correct = referee_scores([params], x, y, labels, physics, arch, K2=K2, seed=seed)
    return summary(losses[0], correct[0])


def referee_losses(params, x, y, physics: Physics, arch: Architecture, *, K2: int = 32, seed: int = 12345):
    """Per-input true losses (K1,), same draws as :func:`referee` (for paired comparisons)."""
    return per_input_loss(jax.random.PRNGKey(seed), cast(params, jnp.float32), x, y, physics, arch, K2)
