"""``gift fit MEAS --add NAME [--add NAME ...]``: add effects, fit them, report the error
before and after (CONTRACTS §4 JSON with ``--json``; text and an error-ladder figure without)."""

from __future__ import annotations

from ._labargs import add_common, figure_dir, key, load

# measured (docs/lab.md section 6): without taps the offsets of all but the smallest nets are
# not identified, and the refit null then rejects a correct weight_error model too often
NO_TAPS_CAVEAT = ("  caution: this file has no taps; without them the refit null rejects a correct weight_error "
                  "model too often\n  (8 of 100 at p < 0.01 on 8-16-8-4, docs/lab.md section 6): a small p here "
                  "does not rule weight_error out")


def add_arguments(parser):
    add_common(parser)
    parser.add_argument("--add", action="append", required=True, metavar="NAME",
                        help="a registered effect (CONTRACTS §2 or a plugin) to add to the model (repeatable, in order)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args):
    from ..lab import fit_effects
    from ..lab._figures import fit_figures

    meas = load(args)
    res = fit_effects(key(args), meas, args.add, shots=args.shots, verbose=not args.quiet)
    out = res.as_json()
    folder = figure_dir(args)
    if folder:
        out["figures"] = fit_figures(res, folder)
    return out


def render(out) -> str:
    ps = ", ".join(f"{k}={v:.4g}" for k, v in out["params"].items())
    lines = [f"model: {' + '.join(out['effects'])} ({ps})",
             f"held-out discrepancy: before {out['discrepancy_before']:.4g} (p = {out['p_value_before']:.3g}) -> "
             f"after {out['discrepancy_after']:.4g} +- {out['se_after']:.2g} (p = {out['p_value_after']:.3g}); "
             f"noise floor {out['noise_floor']:.4g} +- {out['floor_se']:.2g}"]
    if "net_discrepancy_after" in out:
        lines.append(f"fitted weight offsets: p against the refit null ({out['refit_null_replicates']} replicates); "
                     f"discrepancy net of their estimation error {out['net_discrepancy_after']:.4g}")
        if not out.get("refit_null_calibrated", True):
            lines.append(NO_TAPS_CAVEAT)
    lines.append("error ladder:")
    for r in out["ladder"]:
        lines.append(f"  {r['model']:<40s} {r['discrepancy']:10.4g} +- {r['se']:.2g}  p = {r['p_value']:.3g}")
    if out.get("figures"):
        lines.append("figures: " + ", ".join(out["figures"]))
    return "\n".join(lines)
