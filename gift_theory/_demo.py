"""The demo's work as library functions: what ``gift demo`` computes, a notebook can compute.

Three parts, each a function returning plain data (the ``gift demo`` command only parses
arguments, calls them and prints):

* :func:`finetune_part` -- train (or load from the cache), fine-tune one misspecified pair
  against a simulated chip with GIFT and its rivals under one chip budget; each row says why
  a line search kept w0 (:func:`why_kept`); :func:`gift_line` measures the loss along GIFT's
  line (predicted against true) and :func:`plot_finetune` draws it with every method's loss;
* the theory part -- some of the paper's claims as computed verdicts -- belongs to the
  checks (``proofs_checks._cli.demo_part``, found through the ``check`` command's registration);
* :func:`lab_part` -- a chip with a hidden physical effect, measured with taps, diagnosed;
* :func:`calibrate_part` -- the trained network on a chip with fixed per-device errors, calibrated
  (``calibrate``), its test accuracy on the chip before and after, and on an ideal chip.

Progress: every function takes ``progress(i, n, label)``, called before item ``i`` (0-based)
of ``n`` starts; None is silent.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ._errors import GiftInputError

#: the parts of the demo, in order
PARTS = ("finetune", "theory", "lab")


def load_demo_setting(dataset: str, arch, s0: float, seed: int = 0, data_folder: str | None = None):
    """``(ds, arch, w0)``: the data set and weights trained in silico at ``s0`` (cached).

    Like :func:`gift_theory.finetune.load_setting`, plus ``data_folder`` for ``dataset="mnist"``.
    """
    import jax.numpy as jnp

    from ._arch import Architecture
    from ._errors import require
    from ._params import cast
    from .data import load_dataset
    from .training import load_or_train

    arch = Architecture.parse(arch) if isinstance(arch, str) else arch
    require(s0 > 0, f"--s0 {s0}: the assumed noise level must be positive")
    ds = load_dataset(dataset, folder=data_folder)
    require(arch.widths[0] == ds.n_inputs and arch.widths[-1] == ds.n_outputs,
            f"--arch {arch} does not fit dataset {dataset} (inputs {ds.n_inputs}, outputs {ds.n_outputs})")
    w0, _ = load_or_train(dataset, arch, s0=float(s0), seed=int(seed), folder=data_folder, progress=True)
    return ds, arch, cast(w0, jnp.float32)


def why_kept(row: dict) -> dict | None:
    """Why a line-search method returned w0 or a step, from its fine-tuning row.

    Uses the row's ``gift_info`` when the library gave one, else the line search's record.

    Returns
    -------
    dict ``kept_w0`` (bool), ``reason`` (one line), ``confirmation_z`` (the confirmation's
    paired z, NaN when it did not run), ``predicted_gain`` (the fitted line's decrease of the
    chip loss at the best measured step, a C1 - a^2 C2 / 2; NaN without a measured step);
    None for a method without a line search.
    """
    gi = row.get("gift_info") or row.get("info", {}).get("gift_info")
    if gi:
        return {k: gi.get(k, math.nan) for k in ("kept_w0", "reason", "confirmation_z", "predicted_gain")} | (
            {"predicted_gain_pct": gi["predicted_gain_pct"]} if "predicted_gain_pct" in gi else {})
    info = row.get("info", {})
    if "accepted" not in info:
        return None
    se = info.get("confirm_se")
    z = info["confirm_mean"] / se if se else math.nan
    a, C1, C2 = info.get("alpha_best"), info.get("C1"), info.get("C2_fit")
    gain = a * C1 - 0.5 * a * a * C2 if None not in (a, C1, C2) else math.nan
    if info["accepted"]:
        reason = f"the confirmation on fresh shots accepted the step (z = {z:.2f} > {info['z_look']:.2f})"
    elif info.get("reason"):
        reason = info["reason"]
    elif not info.get("observed") or max(info["observed"]) <= 0:
        reason = "no measured step lowered the chip loss"
    else:
        reason = f"confirmation not significant: z = {z:.2f} <= {info['z_look']:.2f}"
    return {"kept_w0": not info["accepted"], "reason": reason, "confirmation_z": z, "predicted_gain": gain}


def finetune_part(dataset: str = "digits", arch="64-32-32-10", s0: float = 0.05, st: float = 0.2, true_effects=(),
                  methods=None, *, seed: int = 0, budget: float = 20, data_folder: str | None = None,
                  progress=None, report=None, curve: bool = True) -> dict:
    """Every method in ``methods`` (plus the retrain oracle) on the same w0 and equally seeded chip.

    Parameters
    ----------
    dataset, arch, s0, st, true_effects : the setting (reference §4 finetune)
    methods : names of :data:`gift_theory.finetune.METHODS` (default all)
    seed, budget : the chip's seed and its budget in chip evaluations per method
    data_folder : the MNIST IDX folder for ``dataset="mnist"``
    progress : ``progress(i, n, label)`` before each method; ``report(row)`` after it
    curve : also measure GIFT's line (:func:`gift_line`)

    Returns
    -------
    dict ``rows`` (one per method, reference §4 keys plus ``oracle_fraction``, ``why`` and a
    JSON-ready ``info``) and ``curve`` (arrays, or None when no line-search method ran).
    """
    from .finetune import METHODS, finetune_on, true_physics

    methods = tuple(METHODS if methods is None else methods)
    if "retrain" not in methods:
        methods += ("retrain",)
    physics = true_physics(st, tuple(true_effects))      # bad input before any training
    ds, arch_, w0 = load_demo_setting(dataset, arch, s0, seed, data_folder)
    rows, kept = [], {}
    for i, m in enumerate(methods):
        if progress:
            progress(i, len(methods), m)
        r = finetune_on(ds, arch_, w0, s0=s0, physics=physics, method=m, seed=seed, budget=budget)
        kept[m] = (r.pop("params"), r.pop("direction"))
        r = {"dataset": dataset, "arch": list(arch_.widths), **r}
        r["why"] = why_kept(r)
        rows.append(r)
        if report:
            report(r)
    oracle = [r for r in rows if r["method"] == "retrain"][0]
    gain = oracle["loss_before"] - oracle["loss_after"]
    for r in rows:
        r["oracle_fraction"] = (r["loss_before"] - r["loss_after"]) / gain if gain != 0 else float("nan")
    line = None
    if curve:
        lined = [r for r in rows if r["method"] in ("gift", "pathwise") and kept[r["method"]][1] is not None
                 and "alphas" in r["info"]]
        if lined:
            r = lined[0]
            line = gift_line(ds, arch_, w0, physics, kept[r["method"]][1], r["info"], method=r["method"])
    for r in rows:
        r["info"] = _plain(r["info"])
        if r.get("gift_info") is not None:
            r["gift_info"] = _plain(r["gift_info"])
    return {"rows": rows, "curve": line}


def _plain(obj):
    """The JSON-friendly part of a method's record (numbers, strings, lists of them)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (bool, int, str)) or obj is None:
        return obj
    try:
        return float(obj)
    except (TypeError, ValueError):
        return str(obj)


def gift_line(ds, arch, w0, physics, direction, info: dict, *, method: str = "gift", points: int = 21) -> dict:
    """GIFT's line: the predicted change dJ(a) = a C1 - a^2 C2 / 2 against the referee's truth
    and the chip's measured points.

    Parameters
    ----------
    ds, arch, w0, physics : the setting (the referee knows ``physics``)
    direction : the line-search direction (pytree like ``w0``); info : its record

    Returns
    -------
    dict of arrays: ``alpha`` (points,), ``truth``/``truth_se`` (points,) the referee's
    J(w0) - J(w0 + a u), ``predicted`` and ``predicted_model_C2`` (points,), ``chip_alpha``,
    ``chip_dJ``, ``chip_se`` (measured points), ``C1``, ``C2``, ``method``.
    """
    from .finetune import referee_losses
    from .finetune._tree import axpy, unit

    u, _ = unit(direction)
    span = 1.5 * max(abs(a) for a in info["alphas"])
    grid = np.linspace(-span, span, points)
    l0 = referee_losses(w0, ds.x_train, ds.y_train, physics, arch)
    truth, truth_se = [], []
    for a in grid:
        d = l0 - referee_losses(axpy(float(a), u, w0), ds.x_train, ds.y_train, physics, arch)
        truth.append(d.mean())
        truth_se.append(d.std(ddof=1) / np.sqrt(d.size))
    C1, C2 = float(info["C1"]), float(info["C2_fit"])
    return {"method": method, "alpha": grid, "truth": np.asarray(truth), "truth_se": np.asarray(truth_se),
            "predicted": grid * C1 - 0.5 * grid ** 2 * C2,
            "predicted_model_C2": grid * C1 - 0.5 * grid ** 2 * float(info["C2_model"]),
            "chip_alpha": np.asarray(info["alphas"]), "chip_dJ": np.asarray(info["observed"]),
            "chip_se": np.asarray(info["observed_se"]), "C1": C1, "C2": C2}


def plot_finetune(rows, curve, *, s0: float, st: float, ax=None):
    """Left: GIFT's line (predicted, true, the chip's points); right: every method's true loss
    after fine-tuning against w0's.

    Parameters
    ----------
    rows : the rows of :func:`finetune_part`; curve : its ``curve``
    ax : two Axes, or None for a new figure

    Returns
    -------
    matplotlib.figure.Figure
    """
    if ax is None:
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    else:
        ax1, ax2 = ax
        fig = ax1.figure
    a = np.asarray(curve["alpha"])
    truth, truth_se = np.asarray(curve["truth"]), np.asarray(curve["truth_se"])
    ax1.plot(a, curve["predicted"], "C0-", label="predicted  a C1 - a² C2/2 (fit)")
    ax1.plot(a, curve["predicted_model_C2"], "C0:", label="predicted with model C2 (in silico)")
    ax1.fill_between(a, truth - 2 * truth_se, truth + 2 * truth_se, color="C1", alpha=0.3)
    ax1.plot(a, truth, "C1-", label="true ΔJ (referee, ±2 se)")
    ax1.errorbar(curve["chip_alpha"], curve["chip_dJ"], yerr=2 * np.asarray(curve["chip_se"]), fmt="ko",
                 label="chip (paired, ±2 se)")
    ax1.axhline(0, color="grey", lw=0.5)
    ax1.set_xlabel("step a along the unit direction")
    ax1.set_ylabel("ΔJ(a) = J(w0) - J(w0 + a u)")
    ax1.set_title(f"{curve['method']}: s0={s0:g}, st={st:g}")
    ax1.legend(fontsize=7)
    names = [r["method"] for r in rows]
    before = rows[0]["loss_before"]
    after = [r["loss_after"] for r in rows]
    colours = ["C2" if v < before - 1e-9 else ("C3" if v > before + 1e-9 else "0.6") for v in after]
    from matplotlib.patches import Patch

    ax2.barh(names, after, color=colours)
    line = ax2.axvline(before, color="k", lw=1, label="w0 (no fine-tuning)")
    ax2.set_xlabel("true loss after fine-tuning (train)")
    ax2.invert_yaxis()
    # what each bar's colour says (the bars carry no label of their own)
    ax2.legend(handles=[line, Patch(color="C2", label="lower loss than w0"), Patch(color="C3", label="higher loss than w0"),
                        Patch(color="0.6", label="w0 returned (the same loss)")], fontsize=7)
    lo, hi = min(after), max(after)
    ax2.set_xlim(max(0.0, lo - 0.1 * (hi - lo)), hi + 0.1 * (hi - lo) + 1e-12)
    if ax is None:
        fig.tight_layout()
    return fig


def parse_hidden(spec: str):
    """The lab part's hidden effect from ``NAME=VALUE`` (awgn is the baseline, not hidden)."""
    from .effects import parse_effect

    e = parse_effect(spec, where="--hidden")
    if e.name == "awgn":
        raise GiftInputError("--hidden: awgn is the baseline, not a hidden effect; e.g. shot=0.03 or laplace")
    return e


def lab_chip(hidden, seed: int = 0):
    """The lab part's chip: 8-16-8-4 tanh weights, 160 inputs, awgn(0.1) plus ``hidden``.

    Returns
    -------
    (params, x (160, 8), physics)
    """
    import jax

    from . import _params
    from ._arch import Architecture
    from .effects import Physics, make_effect

    arch = Architecture((8, 16, 8, 4))
    key = jax.random.PRNGKey(seed)
    params = _params.init_params(jax.random.fold_in(key, 1), arch, gain=1.5)
    params = tuple(_params.Layer(W, 0.3 * jax.random.normal(jax.random.fold_in(key, 10 + l), b.shape))
                   for l, (W, b) in enumerate(params))
    x = np.asarray(jax.random.uniform(jax.random.fold_in(key, 2), (160, 8)))
    if hidden.name == "weight_error":
        hidden = type(hidden)(**{**hidden.param_dict(), "seed": seed})
    return params, x, Physics.of([make_effect("awgn", s=0.1), hidden])


def lab_part(hidden, seed: int = 0, *, save_to: str | None = None, progress=None) -> dict:
    """A chip with a hidden effect, measured with taps (160 inputs x 48 shots), diagnosed.

    Parameters
    ----------
    hidden : an Effect (:func:`parse_hidden`); seed : names the chip and its shots
    save_to : also write the measurement there (.npz, reference §3)
    progress : ``progress(i, n, label)`` before each of the two steps (measure, diagnose)

    Returns
    -------
    dict: the chip's physics, the file, the diagnosis' baseline, ranking (first three), verdict,
    failing layers, mechanisms (first two), seconds.
    """
    import jax

    from .lab import diagnose, save_measurement, simulate_measurement

    t0 = time.perf_counter()
    key = jax.random.PRNGKey(seed)
    params, x, physics = lab_chip(hidden, seed)
    if progress:
        progress(0, 2, "measure the chip (160 inputs x 48 shots, taps)")
    meas = simulate_measurement(jax.random.fold_in(key, 3), params, x, physics, shots=48, taps=True, times=True)
    if save_to:
        save_measurement(save_to, meas)
    if progress:
        progress(1, 2, "diagnose (fit every candidate effect, score on held-out inputs)")
    out = diagnose(jax.random.fold_in(key, 4), meas).as_json()
    return {"chip": physics.describe(), "file": save_to, "baseline": out["baseline"],
            "missing_effect_detected": out["missing_effect_detected"], "ranking": out["ranking"][:3],
            "explained": out["explained"], "verdict": out["verdict"], "failing_layers": out["failing_layers"],
            "mechanisms": out["mechanisms"][:2], "seconds": time.perf_counter() - t0}


#: the calibration part's chip: fixed per-device errors (docs/reference.md §2) on top of the noise
CALIBRATION_CHIP = ("layer_gain=0.7", "bias_offset=0.3", "weight_error=0.03")


def calibrate_part(dataset: str = "digits", arch="64-32-32-10", s0: float = 0.05, *, faults=CALIBRATION_CHIP,
                   seed: int = 0, budget: float = 20, data_folder: str | None = None) -> dict:
    """The network trained at ``s0`` on a simulated chip with noise s0 and the fixed per-device
    errors ``faults`` (with taps), calibrated with ``budget`` chip evaluations.

    Returns
    -------
    dict: ``chip`` (its physics), ``accuracy_before`` / ``accuracy_after`` (test set, the referee:
    the simulator's truth), ``accuracy_ideal`` (w0 on a chip with the noise alone), their standard
    errors, ``recovered`` (the share of the lost accuracy won back), ``evaluations``, ``accepted``,
    ``identified`` (per layer, what calibrate read), ``seconds``.
    """
    from .effects import Physics, awgn
    from .finetune import finetune_on, referee

    t0 = time.perf_counter()
    physics = Physics.parse(list(faults), s=s0, where="calibration chip")
    ds, arch_, w0 = load_demo_setting(dataset, arch, s0, seed, data_folder)
    r = finetune_on(ds, arch_, w0, s0=s0, physics=physics, method="calibrate", seed=seed, budget=budget)
    ideal = referee(w0, ds.x_test, ds.y_test, ds.labels_test, awgn(s0), arch_)
    before, after = r["test_accuracy_before"], r["test_accuracy_after"]
    lost = ideal["accuracy"] - before
    info = r["info"]
    return {"chip": physics.describe(), "accuracy_before": before, "accuracy_after": after,
            "accuracy_ideal": ideal["accuracy"], "accuracy_se": info["referee"]["test_accuracy_change_se"],
            "recovered": (after - before) / lost if lost > 0 else float("nan"),
            "evaluations": r["in_situ_evaluations"], "accepted": bool(info.get("accepted")),
            "reason": info.get("reason", ""), "identified": _plain(info.get("identified", {})),
            "seconds": time.perf_counter() - t0}
