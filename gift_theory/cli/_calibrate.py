"""``gift calibrate MEAS --dataset NAME --out W.npz``: corrected weights for the chip a measurement
file measured, with the predicted accuracy and its 95 % interval (docs/reference.md §7).

The chip model the weights were computed under goes beside them (``W.chip.npz``): after
programming the corrected weights and measuring again, ``gift compare NEW --chip-model W.chip.npz``
scores the prediction against what the chip realised.
"""

from __future__ import annotations

import os

from .._errors import GiftInputError, require
from ._common import add_data_arguments, check_data_folder
from ._plugins import add_plugin_argument, load_plugins


def add_arguments(parser):
    add_plugin_argument(parser)
    parser.add_argument("measurement", metavar="MEAS",
                        help="a measurement of the programmed weights (docs/reference.md §3: .npz, .csv, .nc)")
    add_data_arguments(parser)
    parser.add_argument("--weights", help="weights .npz (W1..WL, b1..bL) for a file that holds none (CSV, netCDF)")
    parser.add_argument("--add", action="append", default=[], metavar="NAME",
                        help="fit these effects as the chip's noise (default: the diagnosis' model), repeatable")
    parser.add_argument("--out", required=True, metavar="W.npz", help="where the corrected weights go")
    parser.add_argument("--no-retrain", action="store_true",
                        help="keep the programmed weights as the target (pre-compensate the maps only)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise fit, the retraining and the prediction")
    parser.add_argument("--draws", type=int, default=40, metavar="B",
                        help="draws of the realised maps behind the prediction's interval (default 40)")


def run(args) -> dict:
    import jax

    from ..calibration import calibrate_measurement
    from ..data import load_dataset
    from ..lab import load_measurement

    check_data_folder(args)
    require(args.out.endswith(".npz"), f"--out {args.out}: the weights are written as .npz (W1.., b1..)")
    require(args.draws >= 2, f"--draws {args.draws}: needs at least 2")
    load_plugins(args)
    meas = load_measurement(args.measurement, weights=args.weights)
    ds = load_dataset(args.dataset, folder=args.data_folder)
    if meas.arch.widths[0] != ds.n_inputs or meas.arch.widths[-1] != ds.n_outputs:
        raise GiftInputError(f"{args.measurement}: the network {'-'.join(map(str, meas.arch.widths))} does not fit "
                             f"--dataset {args.dataset} (inputs {ds.n_inputs}, outputs {ds.n_outputs})")
    res = calibrate_measurement(jax.random.PRNGKey(args.seed), meas, ds, effects=tuple(args.add),
                                retrain=not args.no_retrain, draws=args.draws, source=args.measurement)
    import numpy as np

    from .._io import atomic_write
    from .._params import params_to_arrays

    stem = os.path.splitext(args.out)[0]
    model_path = res.model.save(stem + ".chip.npz")
    arrays = {k: np.asarray(v, np.float64) for k, v in params_to_arrays(res.params).items()}
    atomic_write(args.out, lambda fh: np.savez(fh, **arrays))
    return {**res.as_json(), "out": args.out, "chip_model": model_path}


def render(r: dict) -> str:
    lo, hi = r["predicted_accuracy_interval"]
    blo, bhi = r["accuracy_before_interval"]
    ps = ", ".join(f"{k}={v:.4g}" for k, v in r["params"].items() if isinstance(v, float))
    lines = [f"noise: {' + '.join(r['effects'])} ({ps})",
             f"accuracy on the chip, predicted (test set): programmed {r['accuracy_before']:.3f} [{blo:.3f}, {bhi:.3f}]"
             f" -> corrected {r['predicted_accuracy']:.3f} [{lo:.3f}, {hi:.3f}] (95 %)"]
    for l, d in r["identified"].items():
        lines.append(f"  layer {l}: rows' gains {d['rows_gain_range'][0]:.3g}-{d['rows_gain_range'][1]:.3g}, weights off "
                     f"by {d['weight_deviation_rms']:.3g} rms, biases by {d['bias_deviation_rms']:.3g} rms"
                     + (f", dead neurons {', '.join(str(i + 1) for i in d['dead_neurons'])}" if d["dead_neurons"] else ""))
    for w in r["not_identified"]:
        lines.append(f"  not identified: {w}")
    lines.append(f"corrected weights: {r['out']}; the chip model: {r['chip_model']} "
                 f"(after measuring the corrected weights: gift compare NEW --chip-model {r['chip_model']})")
    return "\n".join(lines)
