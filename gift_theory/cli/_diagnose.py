"""``gift diagnose MEAS``: is a physical effect missing from the model, and which one?

Fits the awgn baseline and every candidate effect on half the inputs, scores them on the
other half (reference §4 JSON with ``--json``; a text report and a figure folder without).
"""

from __future__ import annotations

import argparse
import contextlib

from ._common import Progress
from ._fit import no_taps_caveat
from ._labargs import add_common, figure_dir, figure_processes, key, load, write_manifest


def add_arguments(parser):
    add_common(parser)
    parser.add_argument("--candidates", default=None,
                        help="comma-separated effects to try (default: every registered effect but awgn)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.add_argument("--design", action=argparse.BooleanOptionalAction, default=True,
                        help="design the next measurement when the data do not choose between models or nothing "
                             "explains them (reference §8; --no-design: next_measurement null, the rest unchanged)")
    parser.add_argument("--power-replicates", type=int, default=20, metavar="B",
                        help="when nothing is found missing: simulated files behind the power figures next to "
                             "that verdict (default 20; 0: none)")


def run(args):
    from .._errors import require
    from ..lab import DiagnosisFigures, diagnose

    require(args.power_replicates >= 0, f"--power-replicates {args.power_replicates}: needs 0 or more")
    folder = figure_dir(args, "diagnose")  # a folder of another command's: refused before any work
    processes = figure_processes(folder)  # with 2, a helper process starts now
    meas = load(args)
    cands = [c.strip() for c in args.candidates.split(",") if c.strip()] if args.candidates else None
    # the figures that need only the ranking are drawn while the diagnosis localises
    with DiagnosisFigures(folder, meas=meas, key=key(args), processes=processes) if folder \
            else contextlib.nullcontext() as figures:
        res = diagnose(key(args), meas, candidates=cands, shots=args.shots, verbose=not args.quiet,
                       progress=Progress("gift diagnose: candidates", args.quiet, after=True), design=args.design,
                       ranked=figures.ranked if figures else None)
        return _output(args, meas, res, folder, figures)


def _output(args, meas, res, folder, figures):
    from .._model import named_subkey
    from ..lab import diagnosis_comparison, power_notes, power_of

    out = res.as_json()

    def power():  # the test's power needs no figure: computed while a helper draws them
        # "nothing missing" is only as strong as the test's power at this file's size (the
        # held-out half gift compare scores too): say which classes it could not have seen
        out["power"] = (power_of(named_subkey(key(args), "power"), res.baseline, meas.subset(res.held_out),
                                 replicates=args.power_replicates) if args.power_replicates else [])
        out["power_notes"] = power_notes(out["power"], verdict_passes=True)

    if not res.missing_effect_detected:
        out["power"], out["power_notes"] = [], []  # their place among the keys
    out["model_comparison"] = diagnosis_comparison(res)
    later = power if not res.missing_effect_detected else None
    if folder:
        out["figures"] = figures.finish(res, meanwhile=later)
        write_manifest(folder, "diagnose", args, out["figures"])
    elif later is not None:
        later()
    return out


def render(out) -> str:
    b = out["baseline"]
    lines = [out.get("verdict", ""),
             f"baseline awgn (s = {b['params'].get('s', float('nan')):.4g}): held-out discrepancy "
             f"{b['discrepancy']:.4g} +- {b['se']:.2g}, noise floor {b['noise_floor']:.4g} +- {b['floor_se']:.2g}, "
             f"p = {b['p_value']:.3g}",
             "missing effect detected: " + ("YES (p < 0.01)" if out["missing_effect_detected"] else "no (the baseline passes)"),
             *["  " + n for n in out.get("power_notes", [])]]
    if out.get("failing_layers") is not None:
        fl = out["failing_layers"]
        lines.append("failing layers (one-step check, 0.01 with Bonferroni over the layers): "
                     + (", ".join(map(str, fl)) if fl else "none"))
    if out.get("mechanisms"):
        lines.append("mechanisms the localised evidence points to (reference §6; score in sd, p after "
                     "multiplicity correction):")
        for m in out["mechanisms"]:
            where = f"layers {', '.join(map(str, m['layers']))}" if m["layers"] else "layers ?"
            p = m.get("p_value")
            # a p-value below float range is printed as such, not as a certainty of 0
            ptext = ((f"p = {p:<9.3g}" if p > 0 else f"{'p < 1e-300':<13s}") if isinstance(p, (int, float))
                     else " " * 13)
            lines.append(f"  {m['mechanism']:<22s} {where:<14s} {m['score']:7.1f}  {ptext} {m['evidence']}")
    if out.get("output_explanations"):
        lines.append("without taps, each candidate mechanism put into the model and fitted to the output's mean "
                     "(lack of fit z; it explains the mean below 2.33):")
        for c in out["output_explanations"]:
            lines.append(f"  {c['mechanism']:<22s} {c['parameters']:4d} parameters  z = {c['lack_of_fit_z']:8.1f}  "
                         + ("explains  " if c["explains"] else "          ") + c["candidate"])
    if not out.get("explained", True) and out.get("reasons"):
        lines.append("why not explained: " + "; ".join(out["reasons"]))
    top = (out.get("ranking") or [{}])[0]
    if out.get("explained") and top.get("bought_by"):
        lines.append(top["bought_by"])
    if len(out.get("explained_by") or []) > 1:
        lines.append("explained by each of: " + ", ".join("awgn + " + e for e in out["explained_by"]))
    nxt = out.get("next_measurement")
    if nxt:
        lines.append(f"next measurement: {nxt['design']} -- separates {' / '.join(nxt['separates'])} with power "
                     f"{nxt['power']:.2f} at 0.01 (gift design MEAS --out INPUTS.npz writes the inputs)")
    lines.append("ranking (held-out discrepancy after fitting): the models that pass (by parsimony-penalised "
                 "discrepancy), then those refused by a check of their fitted values, then those the data reject:")
    for i, r in enumerate(out["ranking"], 1):
        ps = ", ".join(f"{k}={v:.4g}" for k, v in r["params"].items() if isinstance(v, (int, float)))
        ps += "".join(f", {k}=[{', '.join(f'{x:.3g}' for x in v)}]" for k, v in r["params"].items()
                      if isinstance(v, list) and 0 < len(v) <= 8)
        name = "awgn alone (the baseline)" if r.get("baseline") else " + ".join(r.get("with", []) + [r["effect"]])
        lines.append(f"  {i:2d}. {name:<28s} {r.get('status', ''):<8s} {r['discrepancy_after']:10.4g}  "
                     f"p = {r['p_value_after']:<9.3g} [{r.get('mechanism', '')}] {ps}")
    if out.get("model_comparison") and len(out["model_comparison"]) > 1:
        first = out["model_comparison"][0]["model"]
        lines.append(f"model comparison on the held-out inputs (difference to {first}, +- its paired bootstrap "
                     f"standard error over the inputs):")
        for t in out["model_comparison"][1:6]:
            lines.append(f"  {t['model']:<32s} {t['delta']:+10.4g} +- {t['delta_se']:.2g}")
    if out.get("not_fitted"):
        lines.append("not fitted: " + ", ".join(r["effect"] for r in out["not_fitted"]) + " -- "
                     + out["not_fitted"][0]["reason"])
    if any("net_discrepancy_after" in r for r in out["ranking"]):
        lines.append("  (fitted offsets: p against the refit null, i.e. net of the offsets' estimation error)")
        if not out.get("refit_null_calibrated", True):
            lines.append(no_taps_caveat(sorted({e for r in out["ranking"] for e in r.get("fitted_offsets", [])})))
    if out.get("where"):
        lines.append("one-step check per layer (layer fed the measured layer before, at its own noise level s):")
        for w in out["where"]:
            lines.append(f"  layer {w['layer']}: discrepancy {w['discrepancy']:.4g} (z = {w['z']:.1f}, "
                         f"p = {w['p_value']:.3g}, s = {w.get('s', float('nan')):.3g}"
                         + (" through its measured transfer" if w.get("s_through_transfer") else "") + ")")
    if out.get("signatures"):
        lines.append("signatures against the baseline (z > 3 stands out):")
        for name, s in out["signatures"].items():
            lines.append(f"  {name:<15s} z = {s['z']:7.2f}  {s['statistic']}")
    if out.get("figures"):
        lines.append("figures: " + ", ".join(out["figures"]))
    return "\n".join(lines)
