"""The ceiling of a fine-tuning line: the referee's best along w0 + a u.

Every method that searches along one direction u (GIFT along the pathwise d/ds grad J_s0,
Algorithm 1 along the printed D^[0], the gradient rival) can at best return the point of the
line w0 + a u that the truth scores best. The referee (true physics, fixed draws, never charged
to the chip) scans a dense set of steps a on the training data -- both signs, log-spaced
relative to |w0|, then refined between the neighbours of the lowest loss -- and the step with
the lowest training loss (and, separately, the one with the highest training accuracy) is
reported with the referee's full draws on the training and the test data. The test numbers
are therefore those of a step chosen without the test data: the most any search along that
line could give.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from .._objective import per_input_scores
from .._phases import phase
from ._directions import direction
from ._tree import axpy, norm, unit, vdot

#: the directions a ceiling is computed along: GIFT's, Algorithm 1's printed D^[0], the plain gradient
CEILING_DIRECTIONS = ("pathwise", "score_paper", "gradient")


def _scores(sets, x, y, labels, physics, arch, K2: int, seed: int, group: int):
    """Mean loss and accuracy of each weight set (common draws), in fixed groups of ``group``
    sets (one compiled program per group size; the last group is padded with its first set)."""
    loss, acc = [], []
    for i in range(0, len(sets), group):
        part = list(sets[i:i + group])
        n = len(part)
        part += [part[0]] * (group - n)
        lo, co = per_input_scores(jax.random.PRNGKey(seed), part, x, y, labels, physics, arch, K2)
        loss += list(np.mean(np.asarray(lo, np.float64), axis=1)[:n])
        acc += list(np.mean(np.asarray(co, np.float64), axis=1)[:n])
    return np.asarray(loss), np.asarray(acc)


def step_grid(rel_min: float = 3e-5, rel_max: float = 1e-1, n_side: int = 15) -> np.ndarray:
    """Relative steps a / |w0|: 0 and +-``n_side`` log-spaced values in [rel_min, rel_max]."""
    r = np.geomspace(rel_min, rel_max, int(n_side))
    return np.concatenate([-r[::-1], [0.0], r])


def line_ceiling(problem, ds, physics, kinds=("pathwise", "score_paper"), *, direction_K2: int = 16,
                 rel_min: float = 3e-5, rel_max: float = 1e-1, n_side: int = 15, refine: int = 5,
                 scan_K2: int = 4, referee_K2: int = 32, referee_seed: int = 12345, group: int = 8) -> dict:
    """The referee's best along w0 + a u for each direction kind.

    Parameters
    ----------
    problem : Problem (its w0, model at s0, training data and key; the chip is not used)
    ds : the data set (training and test inputs, targets, labels)
    physics : the chip's true physics (the referee's)
    kinds : direction kinds (:data:`gift_theory.finetune.DIRECTIONS`); the direction is the
        memoized one the line-search methods use (same K2), so the line is exactly theirs
    rel_min, rel_max, n_side : the scan's relative steps (:func:`step_grid`)
    refine : extra steps spaced evenly between the two neighbours of the scan's lowest loss
    scan_K2 : referee draws per training input during the scan (the same draws at every step)
    referee_K2, referee_seed : the referee's draws for the reported numbers (the draws of
        :func:`gift_theory.finetune.referee`, so w0's numbers equal a fine-tuning run's "before")

    Returns
    -------
    dict with, for w0, ``loss_before``, ``accuracy_before``, ``test_loss_before``,
    ``test_accuracy_before``; for each kind K: ``K_rel_step_loss`` (chosen a / |w0| for the
    lowest training loss), ``K_loss``, ``K_test_loss``, ``K_accuracy``, ``K_test_accuracy``
    (the referee's numbers there), ``K_rel_step_acc``, ``K_accuracy_best``,
    ``K_test_accuracy_at_best`` (at the step of the highest training accuracy), ``K_scan_points``,
    ``K_at_edge`` (a chosen step is the scan's largest: the best may lie beyond it);
    and ``cos_K_gradient`` when "gradient" is among the kinds (cosine of each other direction
    with grad J_s0). ``scan``: per kind, the relative steps and scanned training loss/accuracy.
    """
    w0 = problem.w0
    w_norm = float(norm(w0))
    units, out, scan = {}, {}, {}
    for kind in kinds:
        with phase("direction"):
            d, _ = direction(problem, kind, K2=direction_K2)
        units[kind], _ = unit(d)
    x, y, lab = ds.x_train, ds.y_train, ds.labels_train
    chosen = []
    for kind, u in units.items():
        rel = step_grid(rel_min, rel_max, n_side)
        with phase("ceiling_scan"):
            loss, acc = _scores([axpy(float(r * w_norm), u, w0) for r in rel], x, y, lab, physics, problem.arch,
                                scan_K2, referee_seed, group)
            i = int(np.argmin(loss))
            if refine > 0:
                lo, hi = rel[max(i - 1, 0)], rel[min(i + 1, rel.size - 1)]
                extra = np.linspace(lo, hi, refine + 2)[1:-1]
                extra = extra[~np.isin(extra, rel)]
                l2, a2 = _scores([axpy(float(r * w_norm), u, w0) for r in extra], x, y, lab, physics, problem.arch,
                                 scan_K2, referee_seed, group)
                order = np.argsort(np.concatenate([rel, extra]))
                rel = np.concatenate([rel, extra])[order]
                loss, acc = np.concatenate([loss, l2])[order], np.concatenate([acc, a2])[order]
        r_loss, r_acc = float(rel[int(np.argmin(loss))]), float(rel[int(np.argmax(acc))])
        scan[kind] = {"rel_step": rel.tolist(), "loss": loss.tolist(), "accuracy": acc.tolist()}
        out[f"{kind}_rel_step_loss"], out[f"{kind}_rel_step_acc"] = r_loss, r_acc
        out[f"{kind}_scan_points"] = int(rel.size)
        out[f"{kind}_at_edge"] = bool(max(abs(r_loss), abs(r_acc)) >= rel_max)  # the best may lie beyond the scan
        chosen += [axpy(r_loss * w_norm, u, w0), axpy(r_acc * w_norm, u, w0)]
    with phase("referee"):
        tr = _scores([w0] + chosen, x, y, lab, physics, problem.arch, referee_K2, referee_seed, 1 + len(chosen))
        te = _scores([w0] + chosen, ds.x_test, ds.y_test, ds.labels_test, physics, problem.arch, referee_K2,
                     referee_seed, 1 + len(chosen))
    out.update(loss_before=float(tr[0][0]), accuracy_before=float(tr[1][0]), test_loss_before=float(te[0][0]),
               test_accuracy_before=float(te[1][0]))
    for j, kind in enumerate(units):
        a, b = 1 + 2 * j, 2 + 2 * j
        out.update({f"{kind}_loss": float(tr[0][a]), f"{kind}_test_loss": float(te[0][a]),
                    f"{kind}_accuracy": float(tr[1][a]), f"{kind}_test_accuracy": float(te[1][a]),
                    f"{kind}_accuracy_best": float(tr[1][b]), f"{kind}_test_accuracy_at_best": float(te[1][b])})
    if "gradient" in units:
        g = units["gradient"]
        for kind, u in units.items():
            if kind != "gradient":
                c = float(vdot(u, g))
                out[f"cos_{kind}_gradient"] = c if math.isfinite(c) else math.nan
    out["w0_norm"] = w_norm
    out["scan"] = scan
    return out


def run_ceiling(dataset: str = "digits", arch="64-32-32-10", s0: float = 0.1, st: float = 0.2, true_effects=(),
                seed: int = 0, kinds=("pathwise", "score_paper"), train_epochs: int | None = None, K1=None,
                K2: int = 1, data_folder: str | None = None, **options) -> dict:
    """:func:`line_ceiling` on the setting of :func:`gift_theory.finetune.run_finetune` (same w0,
    same problem key, so the directions are those its line searches use).

    ``data_folder``: the MNIST IDX folder for ``dataset="mnist"``, as in ``run_finetune``.
    ``options`` go to :func:`line_ceiling`; ``referee_K2`` also names the referee's draws.
    """
    from ._problem import make_problem
    from ._run import load_setting, true_physics

    physics = true_physics(st, true_effects)
    with phase("setting"):
        ds, arch_, w0 = load_setting(dataset, arch, s0, seed, train_epochs=train_epochs, progress=False,
                                      data_folder=data_folder)
    problem = make_problem(arch_, w0, ds.x_train, ds.y_train, s0=s0, true_physics=physics, budget=0, K1=K1, K2=K2,
                           seed=seed)
    res = line_ceiling(problem, ds, physics, tuple(kinds), **options)
    return {"dataset": dataset, "arch": list(arch_.widths), "s0": float(s0), "st": float(physics.s), **res}


__all__ = ["CEILING_DIRECTIONS", "line_ceiling", "run_ceiling", "step_grid"]
