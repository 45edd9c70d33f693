"""``gift finetune``: fine-tune in-silico trained weights against a simulated chip or a user's own
chip driver (docs/reference.md §4, §7)."""

from __future__ import annotations

import math

from .._errors import GiftInputError
from ._common import add_data_arguments, check_data_folder, nonneg_float, nonneg_int, positive_float


def add_arguments(parser):
    from ..finetune import METHODS

    add_data_arguments(parser)
    parser.add_argument("--arch", default="64-32-32-10", help="widths d0-...-dL (default 64-32-32-10)")
    parser.add_argument("--s0", type=positive_float, required=True, help="the noise level assumed in training")
    parser.add_argument("--st", type=nonneg_float, default=None,
                        help="the simulated chip's true noise level (required without --chip)")
    parser.add_argument("--chip", default=None, metavar="FILE.py:NAME",
                        help="your own chip: NAME() from FILE.py returns an object of the Chip protocol "
                             "(docs/hardware.md); it replaces the simulated chip, and the scores are measured on it "
                             "with fresh shots the budget does not pay for")
    parser.add_argument("--out", default=None, metavar="W.npz", help="write the returned weights (W1.., b1..) there")
    from ._plugins import add_plugin_argument
    add_plugin_argument(parser)  # calibrate, identify-retrain: effects of your own among the noise candidates
    parser.add_argument("--score-shots", type=int, default=32, metavar="N",
                        help="shots per input of the scores (the referee's, or the chip's with --chip; default 32)")
    parser.add_argument("--true-effect", action="append", default=[], metavar="NAME=VALUE",
                        help="a reference §2 effect the chip also has (repeatable), e.g. shot=0.01")
    parser.add_argument("--method", default="gift", help=f"one of: {', '.join(METHODS)}")
    parser.add_argument("--seed", type=nonneg_int, default=0,
                        help="names the trained weights, the chip's noise and the method's randomness (default 0)")
    parser.add_argument("--budget", type=nonneg_float, default=20, help="chip evaluations allowed (units of Eval(K1, K2))")
    parser.add_argument("--K1", type=int, default=None, help="fine-tuning inputs (default: all training inputs)")
    parser.add_argument("--K2", type=int, default=1, help="shots per input per Eval (default 1)")
    parser.add_argument("--weights", default=None, metavar="FILE.npz",
                        help="fine-tune these weights (W1, b1, ...) instead of training at s0")
    parser.add_argument("--no-confirm", action="store_true",
                        help="gift, ift, gradient, random: take the best measured step without the confirmation "
                             "(a variant, not GIFT)")
    parser.add_argument("--keep-w0", action="store_true",
                        help="gift-printed, pathwise: w0 is a candidate of the final selection (as the paper's text "
                             "says; the printed algorithm does not)")
    parser.add_argument("--eta-pct", type=float, default=None, metavar="P",
                        help="gift-printed, pathwise: eta = P %% of |w0| along D^[0] (default 1)")
    parser.add_argument("--retrain-at", default="chip", choices=("chip", "s0"),
                        help="retrain: at the chip's physics (the oracle, default) or at s0 (its control)")
    parser.add_argument("--train-epochs", type=int, default=None, metavar="N",
                        help="train w0 for N epochs instead of the default recipe's")


def run(args) -> dict:
    from ..finetune import METHODS, run_finetune

    check_data_folder(args)
    if args.method not in METHODS:
        raise GiftInputError(f"--method {args.method!r}: unknown; known: {', '.join(METHODS)}")
    if args.chip is None and args.st is None:
        raise GiftInputError("--st: the simulated chip's noise level is needed (or --chip FILE.py:NAME for your own chip)")
    if args.chip is not None and (args.st is not None or args.true_effect):
        raise GiftInputError("--chip: --st and --true-effect describe a simulated chip; your chip's physics is its own")
    if args.out is not None and not args.out.endswith(".npz"):
        raise GiftInputError(f"--out {args.out}: the weights are written as .npz (W1.., b1..)")
    from ._plugins import load_plugins
    load_plugins(args)
    if args.score_shots < 1:
        raise GiftInputError(f"--score-shots {args.score_shots}: must be at least 1")
    for name, v in (("--s0", args.s0), ("--st", 0.0 if args.st is None else args.st), ("--budget", args.budget)):
        if not math.isfinite(v) or v < 0:
            raise GiftInputError(f"{name} {v}: must be a non-negative number")
    if args.s0 <= 0:
        raise GiftInputError(f"--s0 {args.s0}: must be positive")
    if args.K2 < 1 or (args.K1 is not None and args.K1 < 2):
        raise GiftInputError("--K1 must be at least 2 and --K2 at least 1")
    extra = {}
    line = ("gift", "ift", "gradient", "random")
    printed = ("gift-printed", "pathwise")
    for flag, on, methods, key, value in (
            ("--no-confirm", args.no_confirm, line, "confirm", False),
            ("--keep-w0", args.keep_w0, printed, "keep_w0", True),
            ("--eta-pct", args.eta_pct is not None, printed, "rel_step",
             None if args.eta_pct is None else args.eta_pct / 100),
            ("--retrain-at", args.retrain_at != "chip", ("retrain",), "at", args.retrain_at)):
        if on:
            if args.method not in methods:
                raise GiftInputError(f"{flag}: applies to --method {' | '.join(methods)}, not {args.method}")
            extra[key] = value
    if args.eta_pct is not None and not (math.isfinite(args.eta_pct) and args.eta_pct > 0):
        raise GiftInputError(f"--eta-pct {args.eta_pct}: must be a positive number")
    if args.train_epochs is not None and args.train_epochs < 1:
        raise GiftInputError(f"--train-epochs {args.train_epochs}: must be at least 1")
    if args.train_epochs is not None and args.weights is not None:
        raise GiftInputError("--train-epochs: not with --weights (the weights are given, not trained)")
    out = run_finetune(dataset=args.dataset, arch=args.arch, s0=args.s0, st=args.st,
                       true_effects=tuple(args.true_effect), method=args.method, seed=args.seed,
                       budget=args.budget, K1=args.K1, K2=args.K2, weights=args.weights,
                       train_epochs=args.train_epochs, data_folder=args.data_folder, chip=args.chip, out=args.out,
                       referee_K2=args.score_shots, **extra)
    out["info"] = _plain(out.get("info", {}))
    out["gift_info"] = _plain(out.get("gift_info"))
    return out


def _plain(obj):
    """Keep the JSON-friendly part of a method's info."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (bool, int, str)) or obj is None:
        return obj
    try:
        v = float(obj)
    except (TypeError, ValueError):
        return str(obj)
    return v if math.isfinite(v) else None  # JSON has no NaN: an undefined number is null


def render(r: dict) -> str:
    chip = "your chip" if r.get("st") is None else f"st={r['st']:g}"
    lines = [f"gift finetune  {r['dataset']} {'-'.join(map(str, r['arch']))}  s0={r['s0']:g} -> {chip}  "
             f"method={r['method']}  (scored by {'the chip, fresh shots not charged' if r.get('scored_by') == 'chip' else 'the referee'})",
             f"{'':14}{'before':>10}{'after':>10}",
             f"{'train loss':14}{r['loss_before']:10.4f}{r['loss_after']:10.4f}",
             f"{'train acc':14}{r['accuracy_before']:10.4f}{r['accuracy_after']:10.4f}",
             f"{'test loss':14}{r['test_loss_before']:10.4f}{r['test_loss_after']:10.4f}",
             f"{'test acc':14}{r['test_accuracy_before']:10.4f}{r['test_accuracy_after']:10.4f}",
             f"chip evaluations: {r['in_situ_evaluations']}   seconds: {r['seconds']:.1f}"]
    if r.get("out"):
        lines.append(f"weights written to {r['out']}")
    info = r.get("info") or {}
    if r["method"] == "calibrate" and "rounds" in info:
        lines += _calibrate_lines(info)
    elif r["method"] == "identify-retrain" and "physics" in info:
        p = info.get("baseline_p")
        lines.append(f"identified from {info['inputs']} inputs x {info['shots']} shots "
                     f"({'with taps' if info.get('taps') else 'no taps'}): {info['physics']}"
                     + (f"  (awgn alone: p = {p:.3g}" if p is not None else "  (")
                     + (f"; ranked first: {', '.join(info['ranking'])}" if info.get("ranking") else "")
                     + f"; retrained under {info.get('used', 'it')}; per-device offsets are not used by retraining)")
        if "accepted" in info:
            lines.append(("returned the retrained weights: " if info["accepted"] else "returned w0: ")
                         + str(info.get("reason", "")))
    g = r.get("gift_info")
    if g and r["method"] != "calibrate":
        z, pg = g.get("confirmation_z"), g.get("predicted_gain_pct")
        lines.append(("returned w0: " if g["kept_w0"] else "took a step: ") + g["reason"]
                     + (f"; predicted gain on the line {pg:.2f} %" if pg is not None else ""))
    return "\n".join(lines)


def _calibrate_lines(info: dict) -> list:
    """What calibrate identified and did, in a few lines."""
    out = [f"calibration: {len(info['rounds'])} rounds of measure-and-correct "
           f"({'taps: every layer read' if info.get('taps') else 'no taps: only the output map read'}), "
           f"noise level {info['noise_level']:.4g}, retrained {info['retrained']} time(s)"]
    for l, d in (info.get("identified") or {}).items():
        extra = []
        if d["stuck_weights"] or d["stuck_biases"]:
            extra.append(f"{d['stuck_weights']} stuck weights, {d['stuck_biases']} stuck biases")
        if d["dead_neurons"]:
            extra.append("dead neurons " + ", ".join(str(i + 1) for i in d["dead_neurons"]))
        out.append(f"  layer {l}: rows' gains {d['rows_gain_range'][0]:.3g}-{d['rows_gain_range'][1]:.3g} "
                   f"(median {d['rows_gain_median']:.3g}), weights off by {d['weight_deviation_rms']:.3g} rms, "
                   f"biases by {d['bias_deviation_rms']:.3g} rms" + ("; " + "; ".join(extra) if extra else ""))
    if info.get("rounds"):
        last = info["rounds"][-1]["layers"]
        out.append("  output deficit per layer, first -> last round: " + ", ".join(
            f"{l}: {info['rounds'][0]['layers'][l]['output_deficit']:.3g} -> {last[l]['output_deficit']:.3g}"
            for l in last))
    for what in info.get("not_identified") or []:
        out.append(f"  not identified: {what}")
    if info.get("diagnosis"):
        d = info["diagnosis"]
        out.append(f"  without taps, the lab's diagnosis of the first round: {d['physics']} ({d['used']})")
    out.append(f"returned {info.get('returned', 'w0')}: " + str(info.get("reason", "")))
    return out
