"""``gift compare MEAS [--effect NAME=VALUE ...]``: one discrepancy number of a model
against a measurement file, with its noise floor and p-value.

With ``--effect`` the model is exactly the physics given (nothing fitted, every input
scored); without, the awgn model is fitted on half the inputs and scored on the other half.

Next to the verdict, ``power_notes`` say in words which classes the test could not see at
this file's size (inputs, shots, taps or not), from the power computed on the file
(:func:`gift_theory.lab.power_of`; ``power`` holds the figures).
"""

from __future__ import annotations

from .._errors import require
from ._labargs import MIN_INPUTS_FITTED, MIN_INPUTS_SCORED, add_common, figure_dir, figure_processes, key, load, write_manifest


def add_arguments(parser):
    add_common(parser)
    parser.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                        help="the model's physics (reference §2), e.g. awgn=0.1 shot=0.01; default: fit awgn")
    parser.add_argument("--chip-model", default=None, metavar="M.chip.npz",
                        help="score a fitted chip model (gift calibrate writes one): the weights the file programmed, "
                             "as the model predicts the chip realises them, under its noise (not with --effect)")
    parser.add_argument("--power-replicates", type=int, default=20, metavar="B",
                        help="simulated files behind the power figures next to the verdict (default 20; 0: none)")


def run(args):
    import gift_theory as gt
    from .._model import named_subkey
    from ..lab import compare_measurement, where_it_fails
    from ..lab import compare_figures, power_notes, power_of

    require(args.power_replicates >= 0, f"--power-replicates {args.power_replicates}: needs 0 or more")
    folder = figure_dir(args, "compare")  # a folder of another command's: refused before any work
    processes = figure_processes(folder)  # with 2, a helper process starts now
    meas = load(args, MIN_INPUTS_SCORED if args.effect else MIN_INPUTS_FITTED)  # plugins first: --effect may name one
    physics = None
    if args.chip_model is not None:
        import dataclasses

        from ..calibration import load_chip_model

        if args.effect:
            raise gt.GiftInputError("--chip-model: the model's noise is its own; not with --effect")
        cm = load_chip_model(args.chip_model)
        if tuple(cm.widths) != tuple(meas.arch.widths):
            raise gt.GiftInputError(f"--chip-model {args.chip_model}: a model of a {'-'.join(map(str, cm.widths))} "
                                    f"network, the file measured {'-'.join(map(str, meas.arch.widths))}")
        meas = dataclasses.replace(meas, params=cm.realise(meas.params))
        physics = cm.physics
    elif args.effect:
        specs = list(args.effect)
        if not any(s.strip().split("=")[0].strip() == "awgn" for s in specs):
            raise gt.GiftInputError("--effect: the model needs awgn=S among its effects (the baseline noise level)")
        physics = gt.Physics.parse(specs, where="--effect").check_scope(meas.arch, "--effect")
        need = physics.needs_times()
        if need and meas.t is None:
            raise gt.GiftInputError(f"--effect {need[0]}: {args.measurement} has no acquisition times t, and "
                                    f"{need[0]} acts through them (a hook that takes t)")
        offsets = [n for n in physics.names if gt.effects.REGISTRY[n].offsets_of]
        if offsets:
            raise gt.GiftInputError(f"--effect {offsets[0]}: a model cannot know the device's fixed draws; "
                                    f"use gift fit --add {offsets[0]} (fitted offsets)")
    res = compare_measurement(key(args), meas, physics, shots=args.shots)
    model, c = res["model"], res["comparison"]
    out = {"model": {"effects": model.effects, "params": model.params_json(), "fitted": res["fitted"],
                     **({"chip_model": args.chip_model} if args.chip_model else {})},
           "discrepancy": c.discrepancy, "se": c.se, "noise_floor": c.noise_floor, "floor_se": c.floor_se,
           "p_value": c.p_value, "inputs_scored": res["scored"].n,
           "per_layer": {f"layer{l}": float(v) for l, v in zip(c.layer_ids, c.per_layer)},
           "channel_z": c.as_dict()["channel_z"], "where": res["where"]}
    where = where_it_fails(key(args), model, res["scored"])
    out["worst_cells"] = where["worst"][:10]

    def power():  # the test's power needs no figure: computed while a helper draws them
        out["power"] = (power_of(named_subkey(key(args), "power"), model, res["scored"],
                                 replicates=args.power_replicates) if args.power_replicates else [])
        out["power_notes"] = power_notes(out["power"], verdict_passes=c.p_value >= 0.01)

    out["power"], out["power_notes"] = [], []  # their place among the keys
    if folder:
        out["figures"] = compare_figures(key(args), model, res["scored"], where,
                                         " + ".join(model.effects) + (" (fitted)" if res["fitted"] else ""), folder,
                                         processes=processes, meanwhile=power)
        write_manifest(folder, "compare", args, out["figures"])
    else:
        power()
    return out


def render(out) -> str:
    m = out["model"]
    ps = ", ".join(f"{k}={v:.4g}" for k, v in m["params"].items())
    lines = [f"model {' + '.join(m['effects'])} ({ps}){' fitted on half the inputs' if m['fitted'] else ''}"
             + (f", the weights as the chip model {m['chip_model']} predicts the chip realises them"
                if m.get("chip_model") else ""),
             f"discrepancy {out['discrepancy']:.4g} +- {out['se']:.2g} on {out['inputs_scored']} inputs; "
             f"noise floor {out['noise_floor']:.4g} +- {out['floor_se']:.2g}; p = {out['p_value']:.3g}"
             + ("  -> the model FAILS (p < 0.01)" if out["p_value"] < 0.01 else "  -> consistent with the data"),
             *["  " + n for n in out.get("power_notes", [])],
             "per layer (its part of the discrepancy): " + ", ".join(f"{k} {v:.3g}" for k, v in out["per_layer"].items())]
    if out.get("channel_z"):
        lines.append("channel z per layer (> 3: this aspect of the layer's shots is off):")
        for layer, row in out["channel_z"].items():
            lines.append(f"  {layer}: " + "  ".join(f"{c} {z:5.1f}" for c, z in row.items()))
    for w in out.get("where", []):
        lines.append(f"  one-step layer {w['layer']}: {w['discrepancy']:.4g} (z = {w['z']:.1f}, p = {w['p_value']:.3g})")
    if out.get("worst_cells"):
        lines.append("worst cells:")
        for w in out["worst_cells"][:5]:
            lines.append(f"  layer {w['layer']} neuron {w['neuron']} input {w['input']}: {w['statistic']} z = {w['z']:.1f}")
    if out.get("figures"):
        lines.append("figures: " + ", ".join(out["figures"]))
    return "\n".join(lines)
