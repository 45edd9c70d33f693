"""Arguments shared by ``gift compare``, ``gift diagnose`` and ``gift fit``."""

from __future__ import annotations

import os

import jax

from .._errors import require
from ._plugins import add_plugin_argument, load_plugins


def add_common(parser):
    add_plugin_argument(parser)
    parser.add_argument("measurement", metavar="MEAS", help="measurement file (CONTRACTS §3): .npz, long or wide .csv, netCDF / HDF5 (.nc, .h5)")
    parser.add_argument("--weights", help="weights .npz (W1..WL, b1..bL) for a file that holds none (CSV, netCDF)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the held-out split, the model shots and the fit")
    parser.add_argument("--shots", type=int, default=None, help="model shots per input (default: the measured r)")
    parser.add_argument("--figures", default=None, metavar="DIR",
                        help="folder for the figures (default without --json: MEAS_gift/; with --json: none)")


#: inputs a command needs: a fit on half of them and a held-out test over the other half
#: (compare --effect scores every input: the test over inputs needs 3)
MIN_INPUTS_FITTED, MIN_INPUTS_SCORED = 4, 3


def load(args, min_inputs: int = MIN_INPUTS_FITTED):
    """Load the plugins (a bad one stops here, before any work), then the measurement file,
    refusing one with fewer than ``min_inputs`` inputs (one line naming the file)."""
    from ..lab import load_measurement

    from ..effects import REGISTRY
    from ..effects._physics import scope_error

    load_plugins(args)
    require(args.shots is None or args.shots >= 2, f"--shots {args.shots}: needs at least 2")
    meas = load_measurement(args.measurement, weights=args.weights)
    for name in getattr(args, "plugin_effects", ()):  # a plugin given for this file must act on it
        err = scope_error(REGISTRY[name], meas.arch.depth)
        require(err is None, f"--plugin: {err}")
    require(meas.n >= min_inputs, f"{args.measurement}: has {meas.n} input(s); "
            + ("fitting on half the inputs and testing on the other half needs at least 4"
               if min_inputs == MIN_INPUTS_FITTED else f"the test over inputs needs at least {min_inputs}"))
    require(meas.r >= 4, f"{args.measurement}: has {meas.r} shots per input; the noise floor (random halves of the "
                         f"shots) needs at least 4")
    return meas


def key(args):
    return jax.random.PRNGKey(args.seed)


def figure_dir(args):
    if args.figures:
        return args.figures
    if args.json:
        return None
    stem = os.path.splitext(args.measurement)[0]
    return stem + "_gift"
