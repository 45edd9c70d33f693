"""``run_finetune``: one method on one misspecified pair, scored by the referee (reference §4)."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .._arch import Architecture
from .._errors import require
from .._params import cast
from .._phases import phase
from ..chips import SimulatedChip, chip_scores
from ..effects import Physics
from ._directions import direction
from ._linesearch import gift_printed, paired_line_search, why
from ._predict import candidate, first_order_prediction, realised_change
from ._problem import make_problem, referee_scores, summary
from ._rivals import identify_retrain, pat, retrain, spsa
from ._tree import norm
from ..estimators import paper_constant

#: every method `gift finetune --method` accepts, plus "none" (no fine-tuning)
METHODS = ("gift", "gift-printed", "pathwise", "ift", "gradient", "random", "spsa", "pat", "pat-identified",
           "identify-retrain", "calibrate", "retrain", "none")


def _line(kind):
    def run(problem, **kw):
        with phase("direction"):
            u, dinfo = direction(problem, kind, K2=kw.pop("direction_K2", 16))
        w, info = paired_line_search(problem, u, **kw)
        info["direction"] = dict(dinfo, kind=kind)
        info["_u"] = u  # the direction itself, for curves and figures (not part of the JSON)
        return w, info
    return run


def _printed(problem, eta=None, rel_step: float = 0.01, direction_K2: int = 16, kind: str = "score_paper",
             keep_w0: bool = False):
    D0, dinfo = direction(problem, kind, K2=direction_K2)
    if kind == "pathwise":  # on the printed D^[0]'s scale: E[D^[0]] = -(s0/2) d/ds grad J
        D0 = jax.tree_util.tree_map(lambda a: paper_constant(problem.s0) * a, D0)
    if eta is None:  # the paper gives no eta: a step of 1 % of |w0| along D^[0]
        eta = rel_step * float(norm(problem.w0)) / max(float(norm(D0)), 1e-30)
    w, info = gift_printed(problem, D0, float(eta), keep_w0=keep_w0)
    info["direction"] = dinfo
    info["rel_step"] = float(eta) * float(norm(D0)) / max(float(norm(problem.w0)), 1e-30)
    return w, info


def _pat_identified(problem, **kw):
    return pat(problem, noise="identified", **kw)


def _calibrate(problem, **kw):
    from ..calibration import calibrate
    return calibrate(problem, **kw)


def _none(problem):
    return problem.w0, {}


def _retrain(problem, at: str = "chip"):
    """The oracle retrains at the chip's physics; ``at="s0"`` is its control, the same retraining at
    the model's own awgn(s0) (no noise mismatch: what extra training alone gives)."""
    require(at in ("chip", "s0"), f"retrain: at={at!r}; known: chip, s0")
    require(at == "s0" or getattr(problem.chip, "physics", None) is not None,
            "--method retrain: the oracle knows a simulated chip's physics; a user's chip hides it "
            "(--retrain-at s0 retrains at s0)")
    physics = problem.chip.physics if at == "chip" else problem.model
    return retrain(problem, physics), {"physics": physics.describe(), "at": at}


def _printed_pathwise(problem, **kw):
    return _printed(problem, kind="pathwise", **kw)


#: gift = the repaired line search along the pathwise d/ds grad J (the estimator that needs
#: ~5000x fewer samples than D^[0] for the same error, see `gift bench`); pathwise = the
#: printed Algorithm 1 with the pathwise direction (so gift-printed -> pathwise isolates
#: the estimator, pathwise -> gift the repaired search)
RUNNERS = {
    "gift": _line("pathwise"),
    "gift-printed": _printed,
    "pathwise": _printed_pathwise,
    "ift": _line("ift"),
    "gradient": _line("gradient"),
    "random": _line("random"),
    "spsa": spsa,
    "pat": pat,
    "pat-identified": _pat_identified,
    "identify-retrain": identify_retrain,
    "calibrate": _calibrate,
    "retrain": _retrain,
    "none": _none,
}


def load_setting(dataset: str, arch, s0: float, seed: int = 0, progress: bool = True, weights: str | None = None,
                 train_epochs: int | None = None, data_folder: str | None = None):
    """``(ds, arch, w0)``: the data set and weights trained in silico at s0 (cached), or read
    from the weight file ``weights`` (W1, b1, ... as written by ``gift train``).
    ``train_epochs``: train for this many epochs instead of the default recipe's (an
    under-trained w0; cached under its own key). ``data_folder``: the MNIST IDX folder for
    ``dataset="mnist"``."""
    from .._params import check_params
    from ..data import load_dataset
    from ..training import load_or_train, load_weights

    arch = Architecture.parse(arch) if isinstance(arch, str) else (
        arch if isinstance(arch, Architecture) else Architecture(tuple(arch)))
    require(s0 > 0, f"--s0 {s0}: the assumed noise level must be positive")
    ds = load_dataset(dataset, folder=data_folder)
    require(arch.widths[0] == ds.n_inputs and arch.widths[-1] == ds.n_outputs,
            f"--arch {arch} does not fit dataset {dataset} (inputs {ds.n_inputs}, outputs {ds.n_outputs})")
    if weights is not None:
        w0 = check_params(load_weights(weights)[0], arch, where=weights)
    else:
        config = None
        if train_epochs is not None:
            import dataclasses

            from ..training import default_config

            require(int(train_epochs) >= 1, f"train_epochs {train_epochs}: must be at least 1")
            config = dataclasses.replace(default_config(dataset, arch), epochs=int(train_epochs))
        w0, _ = load_or_train(dataset, arch, s0=float(s0), seed=int(seed), progress=progress, config=config,
                              folder=data_folder)
    return ds, arch, cast(w0, jnp.float32)


def true_physics(st: float, true_effects=()) -> Physics:
    require(st >= 0, f"--st {st}: the true noise level must be non-negative")
    return Physics.parse(list(true_effects), s=float(st), where="--true-effect")


def finetune_on(ds, arch, w0, *, s0: float, physics: Physics, method: str = "gift", seed: int = 0,
                budget: float = 20, K1=None, K2: int = 1, referee_K2: int = 32, chip=None,
                predict_s: float | None = None, prediction_K2: int = 8, **options) -> dict:
    """Run ``method`` on a prepared setting; the reference §4 finetune keys plus ``info``.

    The referee scores w0 and the returned weights on the same draws, loss and accuracy from
    one pass (``info["referee"]``: standard errors of each number and of the paired changes).
    ``chip``: a device of the Chip protocol instead of a simulated chip with ``physics``; a
    user's chip (anything but a :class:`~gift_theory.chips.SimulatedChip`) is scored on its own
    fresh shots, ``referee_K2`` per input, not charged to the budget (``"scored_by": "chip"``;
    ``physics`` may then be None: the chip's physics is unknown).
    ``predict_s``: for a line-search method, also Theorem 1's first-order prediction of the
    change of J_st at the best measured step, in silico with AWGN at ``predict_s`` and
    ``prediction_K2`` draws per training input, against the referee's realised change
    (``info["prediction"]``, :mod:`gift_theory.finetune._predict`).
    """
    require(method in RUNNERS, f"--method {method!r}: unknown; known: {', '.join(METHODS)}")
    user_chip = chip is not None and not isinstance(chip, SimulatedChip)
    require(physics is not None or user_chip, "finetune: the chip's physics is needed without a chip")
    with phase("problem"):
        problem = make_problem(arch, w0, ds.x_train, ds.y_train, s0=s0, true_physics=physics, budget=budget, K1=K1,
                               K2=K2, seed=seed, chip=chip)
    t0 = time.perf_counter()
    with phase("method"):
        params, info = RUNNERS[method](problem, **options)
        params = jax.block_until_ready(cast(params, jnp.float32))
    seconds = time.perf_counter() - t0
    out = {"method": method, "s0": float(s0), "st": None if physics is None else float(physics.s),
           "in_situ_evaluations": problem.evaluations_used(), "seconds": seconds,
           "scored_by": "chip" if user_chip else "referee"}
    u = info.pop("_u", None)
    cand = None
    if predict_s is not None and u is not None and info.get("alpha_best") is not None and not user_chip:
        cand, u_unit = candidate(w0, u, info["alpha_best"])
        with phase("prediction"):
            prediction = first_order_prediction(problem, u_unit, info["alpha_best"], predict_s, info.get("C2_model"),
                                                K2=prediction_K2)
    scores = {}
    for split, x, y, lab in (("", ds.x_train, ds.y_train, ds.labels_train),
                             ("test_", ds.x_test, ds.y_test, ds.labels_test)):
        sets = [w0, params] + ([cand] if cand is not None and split == "" else [])
        with phase("referee"):
            if user_chip:  # the chip's own fresh shots, not charged to the method's budget
                losses, correct = chip_scores(problem.chip, sets, x, y, lab, shots=referee_K2)
            else:
                losses, correct = referee_scores(sets, x, y, lab, physics, arch, K2=referee_K2)
        before, after = summary(losses[0], correct[0]), summary(losses[1], correct[1])
        out[f"{split}loss_before"], out[f"{split}loss_after"] = before["loss"], after["loss"]
        out[f"{split}accuracy_before"], out[f"{split}accuracy_after"] = before["accuracy"], after["accuracy"]
        change = summary(losses[1] - losses[0], correct[1] - correct[0])
        scores.update({f"{split}loss_before_se": before["loss_se"], f"{split}loss_after_se": after["loss_se"],
                       f"{split}accuracy_before_se": before["accuracy_se"],
                       f"{split}accuracy_after_se": after["accuracy_se"],
                       f"{split}loss_change_se": change["loss_se"], f"{split}accuracy_change_se": change["accuracy_se"]})
        if len(sets) == 3:
            prediction.update(realised_change(losses[0], losses[2]))
    info["referee"] = scores
    if cand is not None:
        info["prediction"] = prediction
    # why the method returned what it did (line searches and Algorithm 1; None for the others)
    out["gift_info"] = why(method, w0, params, info)
    out["direction"] = u
    out["info"] = info
    out["params"] = params
    return out


def run_finetune(dataset: str = "digits", arch="64-32-32-10", s0: float = 0.1, st: float | None = 0.2, true_effects=(),
                 method: str = "gift", seed: int = 0, weights: str | None = None, train_epochs: int | None = None,
                 data_folder: str | None = None, chip=None, out: str | None = None, **options) -> dict:
    """Fine-tune weights trained in silico at ``s0`` against a simulated chip at ``st``.

    Parameters
    ----------
    dataset, arch : the setting (weights trained once at s0, then cached)
    s0 : assumed noise level; st : the chip's true level
    true_effects : reference §2 effect specs the chip also has (``"shot=0.01"``, ...)
    method : one of :data:`METHODS`
    seed : names the trained weights, the chip's noise and the method's randomness
    weights : optional weight file to fine-tune instead of training at s0
    train_epochs : train w0 for this many epochs instead of the default recipe's
    data_folder : the MNIST IDX folder for ``dataset="mnist"``
    chip : a user's chip instead of the simulated one: an object of the Chip protocol, or
        ``"FILE.py:NAME"`` (:func:`gift_theory.chips.load_chip`); ``st`` and ``true_effects`` then
        describe nothing and must be None / empty; the scores are the chip's (fresh shots, not charged)
    out : write the returned weights there (.npz with W1.., b1..)
    options : budget (chip evaluations, default 20), K1 (fine-tuning inputs, default all
        training inputs), K2 (shots per input per Eval, default 1), referee_K2, and the
        method's own keywords: ``confirm=False`` (gift, ift, gradient, random: no
        confirmation), ``keep_w0``, ``eta``, ``rel_step`` (gift-printed, pathwise: eta as a
        fraction of |w0|, default 0.01), ``at="s0"`` (retrain: the control at s0)

    Returns
    -------
    dict with the reference §4 finetune keys, plus ``gift_info`` (why a line search or
    Algorithm 1 returned w0 or a step: ``kept_w0``, ``reason``, ``confirmation_z``,
    ``predicted_gain``, ``predicted_gain_pct``; None for the other methods) and ``info``
    (what the method did).
    """
    require(method in RUNNERS, f"--method {method!r}: unknown; known: {', '.join(METHODS)}")
    if chip is not None:
        require(st is None and not true_effects, "--chip: the chip is real; --st and --true-effect describe a "
                                                 "simulated chip and go without --chip")
        physics = None
    else:
        require(st is not None, "--st: the simulated chip's noise level is needed (or --chip FILE.py:NAME)")
        physics = true_physics(st, true_effects)  # bad input is reported before any training
    if out is not None:
        require(str(out).endswith(".npz"), f"--out {out}: the weights are written as .npz")
    arch_ = Architecture.parse(arch) if isinstance(arch, str) else arch
    if isinstance(chip, str):
        from ..chips import load_chip
        chip = load_chip(chip, getattr(arch_, "widths", None))
    with phase("setting"):
        ds, arch_, w0 = load_setting(dataset, arch, s0, seed, weights=weights, train_epochs=train_epochs,
                                      data_folder=data_folder)
    res = finetune_on(ds, arch_, w0, s0=s0, physics=physics, method=method, seed=seed, chip=chip, **options)
    params = res.pop("params")
    res.pop("direction")
    if out is not None:
        from .._io import atomic_write
        from .._params import params_to_arrays

        arrays = {k: np.asarray(v, np.float64) for k, v in params_to_arrays(params).items()}
        atomic_write(out, lambda fh: np.savez(fh, **arrays))
        res["out"] = str(out)
    return {"dataset": dataset, "arch": list(arch_.widths), **res}


def compare_methods(dataset: str = "digits", arch="64-32-32-10", s0: float = 0.1, st: float = 0.2, true_effects=(),
                    methods=METHODS, seed: int = 0, progress=None, keep: bool = False, **options) -> list[dict]:
    """Every method in ``methods`` on the same w0 and the same (fresh, equally seeded) chip.

    Adds ``oracle_fraction``: (loss_before - loss_after) / (loss_before - loss_after of retrain).
    ``keep``: also return each method's ``params`` and line-search ``direction``.
    """
    physics = true_physics(st, true_effects)
    ds, arch_, w0 = load_setting(dataset, arch, s0, seed)
    rows = []
    for m in methods:
        r = finetune_on(ds, arch_, w0, s0=s0, physics=physics, method=m, seed=seed, **options)
        if not keep:
            r.pop("params")
            r.pop("direction")
        rows.append({"dataset": dataset, "arch": list(arch_.widths), **r})
        if progress:
            progress(rows[-1])
    oracle = [r for r in rows if r["method"] == "retrain"]
    if oracle:
        gain = oracle[0]["loss_before"] - oracle[0]["loss_after"]
        for r in rows:
            r["oracle_fraction"] = (r["loss_before"] - r["loss_after"]) / gain if gain != 0 else float("nan")
    return rows


#: the report's grid: misspecified pairs of the issue, and s0 = st
GRID = ((0.05, 0.2), (0.2, 0.05), (0.1, 0.3), (0.3, 0.1), (0.1, 0.1))


def oracle_grid(pairs=GRID, methods=METHODS, *, dataset: str = "digits", arch="64-32-32-10", seed: int = 0,
                true_effects=(), progress=None, **options) -> list[dict]:
    """:func:`compare_methods` over (s0, st) pairs; every row carries ``oracle_fraction``."""
    methods = ("retrain",) + tuple(m for m in methods if m != "retrain")
    rows = []
    for s0, st in pairs:
        rows += compare_methods(dataset, arch, s0, st, tuple(true_effects), methods=methods, seed=seed,
                                progress=progress, **options)
    return rows
