"""``gift simulate``: write a measurement file (reference §3) from a simulated chip.

The hidden-effect data generator: choose the architecture, the programmed weights, the
inputs, the shots and the chip's effects; the file never exists half-written.
"""

from __future__ import annotations

import os

import jax
import numpy as np

from .. import _random
from .._errors import require
from ._plugins import add_plugin_argument, load_plugins


def add_arguments(parser):
    add_plugin_argument(parser)
    parser.add_argument("--arch", help="widths d_0-...-d_L, e.g. 16-32-16-8 (default: from --weights)")
    parser.add_argument("--weights", help=".npz with W1..WL, b1..bL to program (default: random, from --seed)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random weights, inputs and shots")
    parser.add_argument("--activation", default=None, help="tanh (default), identity, sigmoid, sin")
    parser.add_argument("--gain", type=float, default=1.5, help="scale of the random weights (Glorot x gain)")
    parser.add_argument("--inputs", type=int, default=240, help="number of inputs n (uniform in [0, 1]^d_0)")
    parser.add_argument("--shots", type=int, default=64, help="repeated shots r per input")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                        help="a chip effect (reference §2), repeatable: awgn=0.1 shot=0.01 laplace "
                             "quantization=6,2.0 weight_error=e:0.05,seed:3 (default awgn=0.1)")
    parser.add_argument("--chip-model", default=None, metavar="M.chip.npz",
                        help="simulate a saved chip model (gift fit --save-model, gift calibrate): its noise, and "
                             "the weights it predicts the chip realises; the file records the programmed ones. "
                             "--effect changes or adds effects by name; the network is the model's")
    parser.add_argument("--preset", default=None, metavar="NAME",
                        help="start from a preset chip's effects (coherent-mzi-mesh, incoherent-intensity; "
                             "reference §2c); --effect changes or adds effects by name")
    parser.add_argument("--taps", action="store_true", help="also record the hidden layers a1..a{L-1}")
    parser.add_argument("--times", action="store_true",
                        help="also record acquisition times t (always recorded when an effect acts through them: drift, "
                             "a plugin hook that takes t)")
    parser.add_argument("--csv", action="store_true", help="write the long CSV format (weights go to OUT.weights.npz)")
    parser.add_argument("--out", required=True,
                        help="the measurement file to write: .npz, .nc / .h5 (netCDF-4), or .csv (wide; long with "
                             "--csv; the weights then go to OUT.weights.npz)")


def run(args):
    import gift_theory as gt
    from .. import atomic_write
    from .._model import named_subkey
    from ..lab import load_weight_arrays, save_csv, simulate_measurement
    from ..lab import NETCDF_EXTENSIONS, save_file

    load_plugins(args)
    require(args.inputs >= 1, f"--inputs {args.inputs}: needs at least 1")
    require(args.shots >= 2, f"--shots {args.shots}: needs at least 2")
    out = args.out
    folder = os.path.dirname(os.path.abspath(out))
    require(os.path.isdir(folder), f"--out {out}: folder {folder} does not exist")
    ext = os.path.splitext(out)[1].lower()
    require(ext in (".npz", ".csv") + NETCDF_EXTENSIONS or args.csv,
            f"--out {out}: unknown extension {ext or '(none)'!r}; write .npz, .csv or netCDF (.nc, .h5)")
    require(not (args.chip_model and args.preset), "--chip-model and --preset: give one (the model has its own effects)")
    model = None
    if args.chip_model:
        from ..calibration import load_chip_model

        model = load_chip_model(args.chip_model)
        physics = _with_effects(model.physics, args.effect)
    elif args.preset:
        physics = _with_effects(gt.Physics.preset(args.preset), args.effect)
    else:
        specs = list(args.effect) or ["awgn=0.1"]
        if not any(s.strip().split("=")[0].strip() == "awgn" for s in specs):
            specs = ["awgn=0.1"] + specs
        physics = gt.Physics.parse(specs, where="--effect")
    key = jax.random.PRNGKey(args.seed)
    activation = args.activation or (model.activation if model else None)
    if args.weights:
        w = load_weight_arrays(args.weights)
        params = gt.params_from_arrays(w, where=args.weights)
        if activation is None and "activation" in w:
            activation = str(np.asarray(w["activation"]).item())
        arch = gt.arch_of(params, activation or "tanh")
        if args.arch:
            want = gt.Architecture.parse(args.arch)
            require(want.widths == arch.widths, f"--arch {args.arch} does not match the weights in {args.weights} ({arch})")
    else:
        require(args.arch is not None or model is not None,
                "gift simulate: give --arch (e.g. 16-32-16-8) or --weights FILE")
        arch = (gt.Architecture.parse(args.arch, activation=activation or "tanh") if args.arch else
                gt.Architecture(tuple(model.widths), activation))
        params = gt.init_params(named_subkey(key, "weights"), arch, gain=args.gain)
    activation = activation or "tanh"
    require(activation in gt.ACTIVATIONS, f"--activation {activation!r}: known {', '.join(gt.ACTIVATIONS)}")
    if model is not None:
        require(tuple(model.widths) == tuple(arch.widths),
                f"--chip-model {args.chip_model}: a model of a {'-'.join(map(str, model.widths))} network, "
                f"not {'-'.join(map(str, arch.widths))}")
    physics.check_scope(arch, "--effect")
    x = np.asarray(_random.uniform01(named_subkey(key, "inputs"), (args.inputs, arch.widths[0])), np.float64)
    realised = params if model is None else model.realise(params)
    meas = simulate_measurement(named_subkey(key, "shots"), realised, x, physics, shots=args.shots,
                                activation=activation, taps=args.taps, times=args.times)
    if model is not None:  # the file records what was programmed, as a measurement of a real chip does
        import dataclasses

        from .._params import params32

        meas = dataclasses.replace(meas, params=params32(params))
    if args.csv:
        save_csv(out, meas)
        wpath = os.path.splitext(out)[0] + ".weights.npz"
        arrays = {k: v for k, v in meas.arrays().items() if k[:1] in "Wb" or k == "activation"}
        atomic_write(wpath, lambda fh: np.savez(fh, **arrays))
    else:
        save_file(out, meas)  # the format its extension names
    return {"out": out, "n": meas.n, "r": meas.r, "arch": list(meas.arch.widths), "activation": activation,
            "effects": list(physics.names), "params": physics.params_json(), "taps": bool(args.taps),
            "times": meas.t is not None,
            **({"chip_model": args.chip_model, "realised_layers": [r.layer for r in model.responses]}
               if model is not None else {}),
            **({"preset": args.preset} if args.preset else {})}


def _with_effects(physics, specs):
    """``physics`` with the ``--effect`` specs changing (by name) or adding effects."""
    from ..effects import parse_effect

    for spec in specs:
        physics = physics.with_effect(parse_effect(spec, "--effect"))
    return physics


def render(result) -> str:
    return (f"wrote {result['out']}: {result['n']} inputs x {result['r']} shots, arch "
            f"{'-'.join(map(str, result['arch']))} ({result['activation']}), chip effects "
            f"{', '.join(f'{k}={v:g}' if not isinstance(v, list) else f'{k}=[per neuron]' for k, v in result['params'].items())} "
            f"[{', '.join(result['effects'])}]" + (", taps" if result["taps"] else "") + (", times" if result["times"] else "")
            + (f"; the weights as the chip model {result['chip_model']} realises them (layers "
               f"{', '.join(map(str, result['realised_layers'])) or 'none'} differ from the programmed)"
               if "chip_model" in result else "")
            + (f"; preset {result['preset']}" if "preset" in result else ""))
