"""``gift fit MEAS --add NAME [--add NAME ...]``: add effects, fit them, report the error
before and after (reference §4 JSON with ``--json``; text and an error-ladder figure without)."""

from __future__ import annotations

from ._labargs import add_common, figure_dir, figure_processes, key, load, write_manifest

# without taps the offsets of all but the smallest nets are not identified, and the refit null
# then rejects a correct weight_error model too often (docs/record/lab_record.md)
def no_taps_caveat(names) -> str:
    """The caution under a fitted-offset model's p on a file without taps, naming the effects
    whose offsets were fitted (the rate is the one measured, for weight_error)."""
    names = " or ".join(names) or "the fitted offsets"
    return ("  caution: this file has no taps; without them the refit null rejects a correct fitted-offset "
            "model too often\n  (weight_error: 8 of 100 at p < 0.01 on 8-16-8-4, docs/lab.md section 6): "
            f"a small p here does not rule {names} out")


def add_arguments(parser):
    add_common(parser)
    parser.add_argument("--add", action="append", required=True, metavar="NAME",
                        help="a registered effect (reference §2 or a plugin) to add to the model (repeatable, in order)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.add_argument("--replicates", type=int, default=None, metavar="B",
                        help="parametric replicates behind the 95 %% intervals of the moment-fitted parameters "
                             "(default 30)")
    parser.add_argument("--power-replicates", type=int, default=20, metavar="B",
                        help="simulated files behind the power figures next to the verdict on the fitted model "
                             "(default 20; 0: none)")
    parser.add_argument("--save-model", default=None, metavar="M.chip.npz",
                        help="save the fitted model as a chip model (its effects, parameters, intervals, the plugins "
                             "it needs, fitted offsets as realised weights): gift simulate --chip-model draws from it, "
                             "gift compare --chip-model scores it, gt.Physics.load reads its physics")


def run(args):
    import sys

    from ..lab import fit_effects
    from ..lab import fit_figures
    from ..lab import fit_uncertainty

    from .._errors import require

    from .._model import named_subkey
    from ..lab import power_notes, power_of

    require(args.replicates is None or args.replicates >= 2, f"--replicates {args.replicates}: needs at least 2")
    require(args.power_replicates >= 0, f"--power-replicates {args.power_replicates}: needs 0 or more")
    if args.save_model is not None:  # a path that cannot be written is refused before any work
        import os

        require(args.save_model.endswith(".npz"), f"--save-model {args.save_model}: a chip model is written as .npz")
        parent = os.path.dirname(os.path.abspath(args.save_model))
        require(os.path.isdir(parent), f"--save-model {args.save_model}: folder {parent} does not exist")
    folder = figure_dir(args, "fit")  # a folder of another command's: refused before any work
    processes = figure_processes(folder)  # with 2, a helper process starts now
    meas = load(args)
    res = fit_effects(key(args), meas, args.add, shots=args.shots, verbose=not args.quiet)
    out = res.as_json()

    def progress(done, total):
        if not args.quiet and (done == total or done % 10 == 0):
            sys.stderr.write(f"intervals: {done}/{total} parametric replicates\n")
            sys.stderr.flush()

    unc = fit_uncertainty(key(args), meas, res.after, shots=args.shots, B=args.replicates, progress=progress)
    out.update(unc)

    def power():  # the test's power needs no figure: computed while a helper draws them
        # the verdict on the fitted model is only as strong as its test's power at this file's size
        # (the held-out half it was scored on): what the test could not have seen on top of it
        out["power"] = (power_of(named_subkey(key(args), "power"), res.after, meas.subset(res.held_out),
                                 replicates=args.power_replicates) if args.power_replicates else [])
        out["power_notes"] = power_notes(out["power"], verdict_passes=res.comparison_after.p_value >= 0.01)

    out["power"], out["power_notes"] = [], []  # their place among the keys
    from ..lab import comparison_table

    if all(c.channel_values is not None for _, c in res.ladder) and len(res.ladder) > 1:
        out["model_comparison"] = comparison_table([(lab, c, "passes" if c.p_value >= 0.01 else "fails")
                                                    for lab, c in res.ladder][::-1])
    if args.save_model is not None:
        from ..calibration import ChipModel

        scalar = {k: v for k, v in unc.get("intervals", {}).items()}
        out["chip_model"] = ChipModel.from_model(res.after, meas, source=args.measurement,
                                                 intervals=scalar).save(args.save_model)
    if folder:
        from ..lab import where_it_fails

        held = meas.subset(res.held_out)
        where = where_it_fails(named_subkey(key(args), "figure_where"), res.after, held)
        out["figures"] = fit_figures(res, folder, meas=meas, key=key(args), uncertainty=unc, where=where,
                                     processes=processes, meanwhile=power)
        write_manifest(folder, "fit", args, out["figures"])
    else:
        power()
    return out


#: a neuron stands out when its value is this many robust standard errors from the median
STANDOUT_K = 4.0


def standouts(per_neuron: dict, per_neuron_se: dict, k: float = STANDOUT_K) -> list[str]:
    """Lines naming the neurons whose value stands out: ``|value - median| > k sqrt(se^2 +
    spread^2)``, the median and the spread (1.4826 MAD) over every neuron of that parameter,
    se the neuron's own standard error. ``"neuron 2:4 alive 0.0179 +- 0.0052 (others 0.98-1.02)"``
    (layer:neuron, the neuron counted from 0 as everywhere in gift's output: its position in the
    JSON's ``per_neuron`` list, the identification's ``l:i``, the where-figure's rows)."""
    import numpy as np

    lines = []
    for name, layers in per_neuron.items():
        cells = [(int(l), j, float(v), (per_neuron_se.get(name, {}).get(l) or [None] * len(vals))[j])
                 for l, vals in layers.items() for j, v in enumerate(vals)]
        if len(cells) < 3:
            continue
        vals = np.array([c[2] for c in cells])
        med = float(np.median(vals))
        spread = 1.4826 * float(np.median(np.abs(vals - med)))
        out = [c for c in cells if abs(c[2] - med) > k * float(np.hypot(c[3] or 0.0, spread)) and
               (c[3] is not None or spread > 0)]
        rest = [c[2] for c in cells if c not in out]
        others = f"others {min(rest):.3g}-{max(rest):.3g}" if rest else "no others"
        for l, j, v, se in out:
            pm = f" +- {se:.2g}" if se is not None else ""
            lines.append(f"neuron {l}:{j} {name} {v:.4g}{pm} ({others})")
    return lines


def _param(name, value, intervals) -> str:
    if isinstance(value, list):
        return f"{name}=[{len(value)} values per neuron]"
    iv = intervals.get(name)
    return f"{name}={value:.4g}" + (f" [{iv[0]:.4g}, {iv[1]:.4g}]" if iv else "")


def render(out) -> str:
    intervals = out.get("intervals", {})
    ps = ", ".join(_param(k, v, intervals) for k, v in out["params"].items())
    lines = [f"model: {' + '.join(out['effects'])} ({ps})" + ("  [95 % intervals]" if intervals else ""),
             f"held-out discrepancy: before {out['discrepancy_before']:.4g} (p = {out['p_value_before']:.3g}) -> "
             f"after {out['discrepancy_after']:.4g} +- {out['se_after']:.2g} (p = {out['p_value_after']:.3g}); "
             f"noise floor {out['noise_floor']:.4g} +- {out['floor_se']:.2g}",
             *["  " + n for n in out.get("power_notes", [])]]
    if "net_discrepancy_after" in out:
        lines.append(f"fitted offsets: p against the refit null ({out['refit_null_replicates']} replicates); "
                     f"discrepancy net of their estimation error {out['net_discrepancy_after']:.4g}")
        if not out.get("refit_null_calibrated", True):
            lines.append(no_taps_caveat(out.get("fitted_offsets", [])))
    for name, layers in out.get("per_neuron", {}).items():
        n = sum(len(v) for v in layers.values())
        found = [l for l in standouts({name: layers}, out.get("per_neuron_se", {}))]
        lines.append(f"per-neuron {name}: {n} values on layer(s) {', '.join(layers)}; "
                     + (f"{len(found)} stand out (beyond {STANDOUT_K:g} robust standard errors of the median):"
                        if found else f"none stands out (beyond {STANDOUT_K:g} robust standard errors of the median)"))
        lines += ["  " + f for f in found]
    lines.append("error ladder:")
    delta = {t["model"]: t for t in out.get("model_comparison", [])[1:]}
    for r in out["ladder"]:
        d = delta.get(r["model"])
        lines.append(f"  {r['model']:<40s} {r['discrepancy']:10.4g} +- {r['se']:.2g}  p = {r['p_value']:.3g}"
                     + (f"   ({d['delta']:+.4g} +- {d['delta_se']:.2g} against the fitted model, paired over "
                        f"the inputs)" if d else ""))
    if out.get("figures"):
        lines.append("figures: " + ", ".join(out["figures"]))
    if out.get("chip_model"):
        lines.append(f"chip model: {out['chip_model']} (gift simulate --chip-model, gift compare --chip-model)")
    return "\n".join(lines)
