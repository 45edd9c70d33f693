"""``gift demo``: the main job, in three parts (the work is :mod:`gift_theory._demo`).

1. Fine-tuning: train (or load from the cache), fine-tune one misspecified pair against a
   simulated chip with GIFT and its rivals under one chip budget, print one table (a line
   search that kept w0 says so, with its confirmation's z and the line's predicted gain) and
   draw a figure.
2. Theory: two of the paper's claims as computed verdicts (``gift check`` runs them all).
3. The measurement loop: a simulated chip with a hidden physical effect, measured with taps;
   ``diagnose`` says whether the awgn model fails, which effect is missing, and the fitted
   model's error against the noise floor. It ends with a chip calibrated: the trained network on
   a chip with fixed per-device errors, its test accuracy before and after ``calibrate`` and on an
   ideal chip.

``--grid`` runs the report's (s0, st) grid of part 1 instead and prints each method's share
of the retrain oracle's loss gain.
"""

from __future__ import annotations

import os
import shutil
import sys
import textwrap
import time

import numpy as np

from .._demo import PARTS
from .._errors import GiftInputError
from ._common import Progress, add_data_arguments, check_data_folder, nonneg_float, nonneg_int, positive_float


def add_arguments(parser):
    add_data_arguments(parser)
    parser.add_argument("--arch", default=None,
                        help="widths d0-...-dL of the network (default 64-32-32-10; 784-500-100-100-10 for mnist5k/mnist)")
    parser.add_argument("--s0", type=positive_float, default=0.05, help="noise level assumed in training (default 0.05)")
    parser.add_argument("--st", type=nonneg_float, default=0.2, help="the chip's true noise level (default 0.2)")
    parser.add_argument("--true-effect", action="append", default=[], metavar="NAME=VALUE",
                        help="a physical effect the chip also has (repeatable), e.g. shot=0.01; the names: gift --help")
    parser.add_argument("--methods", default=None,
                        help="comma-separated subset of the fine-tuning methods (default all; retrain is always added)")
    parser.add_argument("--budget", type=nonneg_float, default=20, help="chip evaluations per method (default 20)")
    parser.add_argument("--seed", type=nonneg_int, default=0,
                        help="names the trained weights, the chip's noise and every method's randomness (default 0)")
    parser.add_argument("--out", default="gift-out", help="folder for the figure, its data and the lab's measurement "
                                                          "(default gift-out)")
    parser.add_argument("--no-figure", action="store_true", help="write no figure and no files")
    parser.add_argument("--parts", default=",".join(PARTS),
                        help="comma-separated parts to run: finetune, theory, lab (default all)")
    parser.add_argument("--hidden", default="shot=0.03", metavar="NAME=VALUE",
                        help="the hidden effect of the lab part's chip (default shot=0.03)")
    parser.add_argument("--grid", action="store_true",
                        help="run the (s0, st) grid (0.05,0.2) (0.2,0.05) (0.1,0.3) (0.3,0.1) (0.1,0.1) instead")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _methods(spec):
    from ..finetune import METHODS

    if spec is None:
        return METHODS
    ms = tuple(m.strip() for m in spec.split(",") if m.strip())
    bad = [m for m in ms if m not in METHODS]
    if bad or not ms:
        raise GiftInputError(f"--methods: unknown method {bad[0] if bad else spec!r}; known: {', '.join(METHODS)}")
    return ms


def _report(quiet):
    def report(r):
        if quiet:
            return
        sys.stderr.write(f"gift demo:   {r['method']}: loss {r['loss_before']:.4f} -> {r['loss_after']:.4f}, "
                         f"chip evals {r['in_situ_evaluations']}, {r['seconds']:.1f} s\n")
        sys.stderr.flush()
    return report


def run(args):
    from .. import _demo
    from ._common import default_arch

    t0 = time.perf_counter()
    check_data_folder(args)
    arch = args.arch or str(default_arch(args.dataset))
    methods = _methods(args.methods)
    if args.grid:
        from ..finetune import oracle_grid

        if args.data_folder:
            raise GiftInputError("--grid: runs on the cached data sets (digits, mnist5k, teacher), not --dataset mnist")
        rows = oracle_grid(methods=methods, dataset=args.dataset, arch=arch, seed=args.seed,
                           true_effects=tuple(args.true_effect), budget=args.budget,
                           progress=None if args.quiet else _report(False))
        for r in rows:
            r.pop("info", None)
            r.pop("gift_info", None)
        return {"mode": "grid", "dataset": args.dataset, "arch": arch, "budget": args.budget, "rows": rows,
                "true_effects": list(args.true_effect), "seconds": time.perf_counter() - t0}
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    bad = [p for p in parts if p not in PARTS]
    if bad or not parts:
        raise GiftInputError(f"--parts: unknown part {bad[0] if bad else args.parts!r}; parts: {', '.join(PARTS)}")
    hidden = _demo.parse_hidden(args.hidden) if "lab" in parts else None  # bad input before any work
    result = {"mode": "pair", "dataset": args.dataset, "arch": arch, "s0": args.s0, "st": args.st,
              "true_effects": list(args.true_effect), "budget": args.budget, "parts": parts}
    if "finetune" in parts:
        part = _demo.finetune_part(args.dataset, arch, args.s0, args.st, tuple(args.true_effect), methods,
                                   seed=args.seed, budget=args.budget, data_folder=args.data_folder,
                                   progress=Progress("gift demo: fine-tuning", args.quiet), report=_report(args.quiet))
        result["rows"] = part["rows"]
        if part["curve"] is not None:
            result["curve"] = {k: (np.asarray(v).tolist() if not isinstance(v, str) else v)
                               for k, v in part["curve"].items()}
            if not args.no_figure:
                result["figure"] = _save_figure(args, part["rows"], part["curve"])
    if "theory" in parts:
        from ._main import command_module

        check = command_module("check")   # the checks are a package on top of the core
        if check is None:
            raise GiftInputError("--parts theory: the checks are not installed (no 'check' command)")
        result["theory"] = check.demo_part(args.seed, progress=Progress("gift demo: theory", args.quiet))
    if "lab" in parts:
        path = None if args.no_figure else os.path.join(args.out, "demo_chip.npz")
        result["lab"] = _demo.lab_part(hidden, args.seed, save_to=path, progress=Progress("gift demo: lab", args.quiet, eta=False))
        Progress("gift demo: lab", args.quiet, eta=False)(0, 1, "calibrate the trained network on a chip with fixed errors")
        result["lab"]["calibration"] = _demo.calibrate_part(args.dataset, arch, args.s0, seed=args.seed,
                                                            budget=args.budget, data_folder=args.data_folder)
    result["seconds"] = time.perf_counter() - t0
    return result


def _save_figure(args, rows, curve) -> str:
    import matplotlib

    matplotlib.use("agg")  # the command writes files; a notebook calls plot_finetune itself
    from .. import _demo
    from .._io import atomic_write, save_figure

    os.makedirs(args.out, exist_ok=True)
    stem = os.path.join(args.out, f"demo_{args.dataset}_s0{args.s0:g}_st{args.st:g}")
    atomic_write(stem + ".npz", lambda fh: np.savez(
        fh, **{k: v for k, v in curve.items()}, methods=np.asarray([r["method"] for r in rows]),
        loss_after=np.asarray([r["loss_after"] for r in rows]), loss_before=rows[0]["loss_before"]))
    fig = _demo.plot_finetune(rows, curve, s0=args.s0, st=args.st)
    return save_figure(fig, stem + ".png", bbox_inches=None)


# ------------------------------------------------------------------------------------------
# the text form: everything printed whole, long text wrapped
# ------------------------------------------------------------------------------------------
def _width() -> int:
    return max(80, min(120, shutil.get_terminal_size((100, 24)).columns))


def _wrap(text: str, first: str, indent: int) -> list:
    return textwrap.wrap(text, width=_width(), initial_indent=first, subsequent_indent=" " * indent,
                         break_long_words=False, break_on_hyphens=False) or [first]


def render(result) -> str:
    if result["mode"] == "grid":
        return render_grid(result)
    lines = []
    if "rows" in result:
        lines += _render_finetune(result)
    if "theory" in result:
        th = result["theory"]
        lines += ["", f"2. theory: {len(th['checks'])} of the paper's claims as computed verdicts "
                      f"(gift check runs all {th['total_checks']})"]
        for c in th["checks"]:
            lines.append(f"  {c['id']}: {c['verdict']}")
            lines += _wrap(f"evidence: {c['evidence']}", "    ", 6)
            if c.get("correction"):
                lines += _wrap(f"correction: {c['correction']}", "    ", 6)
    if "lab" in result:
        lines += _render_lab(result["lab"])
    lines.append(f"total {result['seconds']:.0f} s")
    return "\n".join(lines)


def _kept(r) -> str:
    w = r.get("why")
    if not w:
        return ""
    z, g = w.get("confirmation_z"), w.get("predicted_gain")
    zs = "no confirmation" if z is None or z != z else f"z = {z:.2f}"
    gs = "" if g is None or g != g else f", predicted gain {g:.3g}"
    return f"  {'kept w0' if w['kept_w0'] else 'took a step'} ({zs}{gs})"


def _render_finetune(result) -> list:
    rows = result["rows"]
    extra = " + " + ", ".join(result["true_effects"]) if result["true_effects"] else ""
    lines = [f"1. fine-tuning: {result['dataset']} {result['arch']}, trained at s0={result['s0']:g}, chip at "
             f"st={result['st']:g}{extra}, budget {result['budget']:g} chip evaluations", "",
             f"{'method':<17}{'loss before':>12}{'loss after':>11}{'acc before':>11}{'acc after':>10}"
             f"{'test acc':>9}{'chip evals':>11}{'seconds':>9}{'of oracle':>10}"]
    for r in rows:
        lines.append(f"{r['method']:<17}{r['loss_before']:12.4f}{r['loss_after']:11.4f}{r['accuracy_before']:11.4f}"
                     f"{r['accuracy_after']:10.4f}{r['test_accuracy_after']:9.4f}{r['in_situ_evaluations']:11d}"
                     f"{r['seconds']:9.1f}{100 * r.get('oracle_fraction', float('nan')):9.0f}%" + _kept(r))
    lines.append("")
    lines.append("loss = true in-situ loss on the training data (referee: the simulator's truth, 32 draws per input);")
    lines.append("'of oracle' = loss gain as a share of retraining at the true physics (which needs st known).")
    whys = [r for r in rows if r.get("why")]
    if whys:
        lines += _wrap("why each line search returned what it did (the chip's view; 'predicted gain' is the fitted "
                       "line a C1 - a^2 C2 / 2 at the best measured step, in loss units):", "", 2)
        for r in whys:
            lines += _wrap(f"{r['method']}: {'kept w0' if r['why']['kept_w0'] else 'took the step'} -- "
                           f"{r['why']['reason']}", "  ", 4)
    if "figure" in result:
        lines.append(f"figure: {result['figure']}")
    return lines


def _render_lab(lab) -> list:
    b = lab["baseline"]
    lines = ["", f"3. measurement loop: a chip with a hidden effect ({lab['chip']}; the model is not told)"]
    lines += _wrap(f"awgn model (s fitted = {b['params']['s']:.4g}): discrepancy {b['discrepancy']:.4g} against a "
                   f"noise floor {b['noise_floor']:.4g} +- {b['floor_se']:.2g}, p = {b['p_value']:.3g} -> "
                   + ("a physical effect is MISSING" if lab["missing_effect_detected"] else "nothing missing"), "  ", 4)
    lines.append("  most likely missing (fitted, scored on held-out inputs):")
    for i, r in enumerate(lab["ranking"], 1):
        name = "awgn alone (baseline)" if r.get("baseline") else " + ".join(r.get("with", []) + [r["effect"]])
        ps = ", ".join(f"{k}={v:.3g}" for k, v in r["params"].items() if isinstance(v, (int, float)))
        lines.append(f"   {i}. {name:<24s} discrepancy {r['discrepancy_after']:8.4g}  p = {r['p_value_after']:.3g}  ({ps})")
    if lab.get("failing_layers") is not None:
        lines.append(f"  layers failing their one-step check: {', '.join(map(str, lab['failing_layers'])) or 'none'}; "
                     f"mechanism: " + (", ".join(m["mechanism"] for m in lab.get("mechanisms", [])) or "none"))
    lines += _wrap(lab["verdict"], "  ", 4)
    if lab.get("file"):
        lines.append(f"  the measurement: {lab['file']} (gift diagnose / gift fit --add NAME on it)")
    c = lab.get("calibration")
    if c:
        lines += _wrap(f"calibrated: the trained network on a chip with fixed errors ({c['chip']}), read with taps "
                       f"and corrected in {c['evaluations']} chip evaluations -- test accuracy on the chip "
                       f"{c['accuracy_before']:.3f} -> {c['accuracy_after']:.3f} (+- {c['accuracy_se']:.3f}); on an "
                       f"ideal chip {c['accuracy_ideal']:.3f}: {100 * c['recovered']:.0f} % of the lost accuracy "
                       f"recovered ({'confirmed on the chip' if c['accepted'] else 'w0 kept: ' + c['reason']})",
                       "  ", 4)
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
