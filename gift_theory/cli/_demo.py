"""``gift demo``: the main job, in three parts.

1. Fine-tuning: train (or load from the cache) on digits, fine-tune one misspecified pair
   against a simulated chip with GIFT and its rivals under one chip budget, print one table
   and draw a figure (the predicted vs observed loss change along GIFT's line, and every
   method's loss).
2. Theory: two of the paper's claims as computed verdicts (``gift check`` runs them all).
3. The measurement loop: a simulated chip with a hidden physical effect, measured with
   taps; ``diagnose`` says whether the awgn model fails, which effect is missing, and the
   fitted model's error against the noise floor (``gift diagnose`` / ``gift fit``).

``--grid`` runs the report's (s0, st) grid of part 1 instead and prints each method's share
of the retrain oracle's loss gain; ``--parts`` picks parts.

A thin shell: the work is :func:`gift_theory.finetune.compare_methods` and
:func:`gift_theory.finetune.oracle_grid`.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from .._errors import GiftInputError
from .._io import atomic_write, save_figure


def add_arguments(parser):
    parser.add_argument("--dataset", default="digits")
    parser.add_argument("--arch", default="64-32-32-10")
    parser.add_argument("--s0", type=float, default=0.05, help="noise level assumed in training (default 0.05)")
    parser.add_argument("--st", type=float, default=0.2, help="the chip's true noise level (default 0.2)")
    parser.add_argument("--true-effect", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--methods", default=None, help="comma-separated subset of the fine-tuning methods")
    parser.add_argument("--budget", type=float, default=20, help="chip evaluations per method (default 20)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="gift-out", help="folder for the figure and its data (default gift-out)")
    parser.add_argument("--no-figure", action="store_true")
    parser.add_argument("--parts", default="finetune,theory,lab",
                        help="comma-separated parts to run: finetune, theory, lab (default all)")
    parser.add_argument("--hidden", default="shot=0.03", metavar="NAME=VALUE",
                        help="the hidden effect of the lab part's chip (default shot=0.03)")
    parser.add_argument("--grid", action="store_true",
                        help="run the (s0, st) grid (0.05,0.2) (0.2,0.05) (0.1,0.3) (0.3,0.1) (0.1,0.1) instead")


def _methods(spec):
    from ..finetune import METHODS

    if spec is None:
        return METHODS
    ms = tuple(m.strip() for m in spec.split(",") if m.strip())
    bad = [m for m in ms if m not in METHODS]
    if bad or not ms:
        raise GiftInputError(f"--methods: unknown method {bad[0] if bad else spec!r}; known: {', '.join(METHODS)}")
    return ms


def _progress(r):
    sys.stderr.write(f"gift demo: s0={r['s0']:g} st={r['st']:g} {r['method']:<16} loss {r['loss_before']:.4f} -> "
                     f"{r['loss_after']:.4f}  chip evals {r['in_situ_evaluations']:>2}  {r['seconds']:.1f}s\n")
    sys.stderr.flush()


def run(args):
    from ..finetune import oracle_grid

    t0 = time.perf_counter()
    methods = _methods(args.methods)
    if args.s0 <= 0 or args.st < 0 or args.budget < 0:
        raise GiftInputError("gift demo: --s0 must be positive, --st and --budget non-negative")
    if args.grid:
        rows = oracle_grid(methods=methods, dataset=args.dataset, arch=args.arch, seed=args.seed,
                           true_effects=tuple(args.true_effect), budget=args.budget, progress=_progress)
        for r in rows:
            r.pop("info", None)
        return {"mode": "grid", "dataset": args.dataset, "arch": args.arch, "budget": args.budget, "rows": rows,
                "true_effects": list(args.true_effect), "seconds": time.perf_counter() - t0}
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    bad = [p for p in parts if p not in PARTS]
    if bad or not parts:
        raise GiftInputError(f"--parts: unknown part {bad[0] if bad else args.parts!r}; parts: {', '.join(PARTS)}")
    hidden = _hidden(args.hidden) if "lab" in parts else None  # bad input before any work
    result = {"mode": "pair", "dataset": args.dataset, "arch": args.arch, "s0": args.s0, "st": args.st,
              "true_effects": list(args.true_effect), "budget": args.budget, "parts": parts}
    if "finetune" in parts:
        result.update(_finetune(args, methods))
    if "theory" in parts:
        result["theory"] = _theory(args)
    if "lab" in parts:
        result["lab"] = _lab(args, hidden)
    result["seconds"] = time.perf_counter() - t0
    return result


PARTS = ("finetune", "theory", "lab")
#: the claims part 2 shows: a symbolic one and a closed-form one (seconds each)
THEORY_CHECKS = ("score_function_identity", "linear_example_bound")


def _finetune(args, methods) -> dict:
    from ..finetune import compare_methods

    if "retrain" not in methods:
        methods = tuple(methods) + ("retrain",)
    rows = compare_methods(args.dataset, args.arch, args.s0, args.st, tuple(args.true_effect), methods=methods,
                           seed=args.seed, progress=_progress, keep=True, budget=args.budget)
    out = {}
    curve = _curve(args, rows)
    for r in rows:
        r.pop("params")
        r.pop("direction")
        r["info"] = {k: v for k, v in r["info"].items() if isinstance(v, (int, float, bool, str, list))}
    out["rows"] = rows
    if curve is not None:
        out["curve"] = {k: np.asarray(v).tolist() for k, v in curve.items()}
        if not args.no_figure:
            out["figure"] = _figure(args, rows, curve)
    return out


def _theory(args) -> list:
    from proofs_checks import run_checks

    sys.stderr.write("gift demo: theory: " + ", ".join(THEORY_CHECKS) + "\n")
    return run_checks(THEORY_CHECKS, seed=args.seed)


def _hidden(spec: str):
    from ..effects import parse_effect

    e = parse_effect(spec, where="--hidden")
    if e.name == "awgn":
        raise GiftInputError("--hidden: awgn is the baseline, not a hidden effect; e.g. shot=0.03 or laplace")
    return e


def _lab(args, hidden) -> dict:
    """A chip with a hidden effect, measured with taps, diagnosed and fitted."""
    import jax

    import gift_theory as gt
    from ..lab import diagnose, save_measurement, simulate_measurement

    t0 = time.perf_counter()
    arch = gt.Architecture((8, 16, 8, 4))
    key = jax.random.PRNGKey(args.seed)
    params = gt.init_params(jax.random.fold_in(key, 1), arch, gain=1.5)
    params = tuple(gt.Layer(W, 0.3 * jax.random.normal(jax.random.fold_in(key, 10 + l), b.shape))
                   for l, (W, b) in enumerate(params))
    x = np.asarray(jax.random.uniform(jax.random.fold_in(key, 2), (160, 8)))
    if hidden.name == "weight_error":
        hidden = type(hidden)(**{**hidden.param_dict(), "seed": args.seed})
    physics = gt.Physics.of([gt.make_effect("awgn", s=0.1), hidden])
    meas = simulate_measurement(jax.random.fold_in(key, 3), params, x, physics, shots=48, taps=True, times=True)
    path = None
    if not args.no_figure:
        os.makedirs(args.out, exist_ok=True)
        path = os.path.join(args.out, "demo_chip.npz")
        save_measurement(path, meas)
    sys.stderr.write(f"gift demo: lab: chip {arch} with a hidden effect, 160 inputs x 48 shots, taps; diagnosing ...\n")
    d = diagnose(jax.random.fold_in(key, 4), meas)
    out = d.as_json()
    return {"chip": physics.describe(), "file": path, "baseline": out["baseline"],
            "missing_effect_detected": out["missing_effect_detected"], "ranking": out["ranking"][:3],
            "explained": out["explained"], "verdict": out["verdict"], "failing_layers": out["failing_layers"],
            "mechanisms": out["mechanisms"][:2], "seconds": time.perf_counter() - t0}


def _curve(args, rows):
    """GIFT's line: predicted dJ(a) = a C1 - a^2 C2 / 2 against the chip's points and the truth."""
    from ..finetune import load_setting, referee_losses, true_physics

    gift = [r for r in rows if r["method"] in ("gift", "pathwise") and r.get("direction") is not None
            and "alphas" in r["info"]]
    if not gift:
        return None
    r = gift[0]
    info = r["info"]
    ds, arch, w0 = load_setting(args.dataset, args.arch, args.s0, args.seed, progress=False)
    physics = true_physics(args.st, tuple(args.true_effect))
    from ..finetune._tree import axpy, unit

    u, _ = unit(r["direction"])
    span = 1.5 * max(abs(a) for a in info["alphas"])
    grid = np.linspace(-span, span, 21)
    l0 = referee_losses(w0, ds.x_train, ds.y_train, physics, arch)
    truth, truth_se = [], []
    for a in grid:
        d = l0 - referee_losses(axpy(float(a), u, w0), ds.x_train, ds.y_train, physics, arch)
        truth.append(d.mean())
        truth_se.append(d.std(ddof=1) / np.sqrt(d.size))
    C1, C2 = info["C1"], info["C2_fit"]
    return {"method": np.asarray(r["method"]), "alpha": grid, "truth": np.asarray(truth),
            "truth_se": np.asarray(truth_se), "predicted": grid * C1 - 0.5 * grid ** 2 * C2,
            "predicted_model_C2": grid * C1 - 0.5 * grid ** 2 * info["C2_model"],
            "chip_alpha": np.asarray(info["alphas"]), "chip_dJ": np.asarray(info["observed"]),
            "chip_se": np.asarray(info["observed_se"]), "C1": C1, "C2": C2}


def _figure(args, rows, curve) -> str:
    import matplotlib

    matplotlib.use("agg")
    import matplotlib.pyplot as plt

    os.makedirs(args.out, exist_ok=True)
    stem = f"demo_{args.dataset}_s0{args.s0:g}_st{args.st:g}"
    data = os.path.join(args.out, stem + ".npz")
    atomic_write(data, lambda fh: np.savez(fh, **curve, methods=np.asarray([r["method"] for r in rows]),
                                           loss_after=np.asarray([r["loss_after"] for r in rows]),
                                           loss_before=rows[0]["loss_before"]))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    a = curve["alpha"]
    ax1.plot(a, curve["predicted"], "C0-", label="predicted  a C1 - a² C2/2 (fit)")
    ax1.plot(a, curve["predicted_model_C2"], "C0:", label="predicted with model C2 (in silico)")
    ax1.fill_between(a, curve["truth"] - 2 * curve["truth_se"], curve["truth"] + 2 * curve["truth_se"], color="C1",
                     alpha=0.3)
    ax1.plot(a, curve["truth"], "C1-", label="true ΔJ (referee, ±2 se)")
    ax1.errorbar(curve["chip_alpha"], curve["chip_dJ"], yerr=2 * curve["chip_se"], fmt="ko", label="chip (paired, ±2 se)")
    ax1.axhline(0, color="grey", lw=0.5)
    ax1.set_xlabel("step a along the unit direction")
    ax1.set_ylabel("ΔJ(a) = J(w0) - J(w0 + a u)")
    ax1.set_title(f"{curve['method']}: s0={args.s0:g}, st={args.st:g}")
    ax1.legend(fontsize=7)
    names = [r["method"] for r in rows]
    before = rows[0]["loss_before"]
    ax2.barh(names, [r["loss_after"] for r in rows], color=["C2" if r["loss_after"] < before - 1e-9 else ("C3" if r["loss_after"] > before + 1e-9 else "0.6")
                                                       for r in rows])
    ax2.axvline(before, color="k", lw=1, label="w0 (no fine-tuning)")
    ax2.set_xlabel("true loss after fine-tuning (train)")
    ax2.invert_yaxis()
    ax2.legend(fontsize=7)
    lo = min(r["loss_after"] for r in rows)
    hi = max(r["loss_after"] for r in rows)
    ax2.set_xlim(max(0.0, lo - 0.1 * (hi - lo)), hi + 0.1 * (hi - lo))
    fig.tight_layout()
    path = os.path.join(args.out, stem + ".png")
    return save_figure(fig, path, bbox_inches=None)


def render(result) -> str:
    if result["mode"] == "grid":
        return render_grid(result)
    lines = []
    if "rows" in result:
        lines += _render_finetune(result)
    if "theory" in result:
        lines += ["", "2. theory: the paper's claims as computed verdicts (all twelve: gift check)"]
        for c in result["theory"]:
            lines.append(f"  {c['id']:<28s} {c['verdict']:<13s} {c['evidence'][:110]}")
            if c.get("correction"):
                lines.append(f"  {'':<28s} correction: {c['correction'][:100]}")
    if "lab" in result:
        lab = result["lab"]
        b = lab["baseline"]
        lines += ["", f"3. measurement loop: a chip with a hidden effect ({lab['chip']}; the model is not told)",
                  f"  awgn model (s fitted = {b['params']['s']:.4g}): discrepancy {b['discrepancy']:.4g} against a "
                  f"noise floor {b['noise_floor']:.4g} +- {b['floor_se']:.2g}, p = {b['p_value']:.3g} -> "
                  + ("a physical effect is MISSING" if lab["missing_effect_detected"] else "nothing missing"),
                  "  most likely missing (fitted, scored on held-out inputs):"]
        for i, r in enumerate(lab["ranking"], 1):
            name = " + ".join(r.get("with", []) + [r["effect"]])
            ps = ", ".join(f"{k}={v:.3g}" for k, v in r["params"].items() if isinstance(v, (int, float)))
            lines.append(f"   {i}. {name:<24s} discrepancy {r['discrepancy_after']:8.4g}  p = {r['p_value_after']:.3g}  ({ps})")
        if lab.get("failing_layers") is not None:
            lines.append(f"  layers failing their one-step check: {', '.join(map(str, lab['failing_layers'])) or 'none'}; "
                         f"mechanism: " + (", ".join(m["mechanism"] for m in lab.get("mechanisms", [])) or "none"))
        lines.append(f"  {lab['verdict']}")
        if lab.get("file"):
            lines.append(f"  the measurement: {lab['file']} (gift diagnose / gift fit --add NAME on it)")
    lines.append(f"total {result['seconds']:.0f} s")
    return "\n".join(lines)


def _render_finetune(result) -> list:
    rows = result["rows"]
    lines = [f"1. fine-tuning: {result['dataset']} {result['arch']}, trained at s0={result['s0']:g}, chip at "
             f"st={result['st']:g}{' + ' + ', '.join(result['true_effects']) if result['true_effects'] else ''}, "
             f"budget {result['budget']:g} chip evaluations", "",
             f"{'method':<17}{'loss before':>12}{'loss after':>11}{'acc before':>11}{'acc after':>10}"
             f"{'test acc':>9}{'chip evals':>11}{'seconds':>9}{'of oracle':>10}"]
    for r in rows:
        lines.append(f"{r['method']:<17}{r['loss_before']:12.4f}{r['loss_after']:11.4f}{r['accuracy_before']:11.4f}"
                     f"{r['accuracy_after']:10.4f}{r['test_accuracy_after']:9.4f}{r['in_situ_evaluations']:11d}"
                     f"{r['seconds']:9.1f}{100 * r.get('oracle_fraction', float('nan')):9.0f}%")
    lines.append("")
    lines.append("loss = true in-situ loss on the training data (referee: the simulator's truth, 32 draws per input);")
    lines.append("'of oracle' = loss gain as a share of retraining at the true physics (which needs st known).")
    if "figure" in result:
        lines.append(f"figure: {result['figure']}")
    return lines


def render_grid(result) -> str:
    rows = result["rows"]
    pairs = []
    for r in rows:
        if (r["s0"], r["st"]) not in pairs:
            pairs.append((r["s0"], r["st"]))
    methods = []
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
    head = f"{'method':<17}" + "".join(f"{f'{a:g}->{b:g}':>13}" for a, b in pairs)
    extra = result.get("true_effects") or []
    lines = [f"share of the retrain-oracle loss gain, {result['dataset']} {result['arch']}"
             f"{', chip also ' + ', '.join(extra) if extra else ''}, "
             f"<= {result['budget']:g} chip evaluations (chip evals used in brackets)", "", head]
    for m in methods:
        cells = []
        for p in pairs:
            r = [x for x in rows if x["method"] == m and (x["s0"], x["st"]) == p][0]
            cells.append(f"{100 * r['oracle_fraction']:7.0f}% ({r['in_situ_evaluations']:>2})")
        lines.append(f"{m:<17}" + "".join(f"{c:>13}" for c in cells))
    gains = []
    for p in pairs:
        r = [x for x in rows if x["method"] == "retrain" and (x["s0"], x["st"]) == p][0]
        gains.append(f"{r['loss_before']:.3f}->{r['loss_after']:.3f}")
    lines.append(f"{'(oracle loss)':<17}" + "".join(f"{g:>13}" for g in gains))
    lines.append(f"total {result['seconds']:.0f} s")
    return "\n".join(lines)
