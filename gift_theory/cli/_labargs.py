"""Arguments shared by ``gift compare``, ``gift diagnose`` and ``gift fit``."""

from __future__ import annotations

import os

import jax

from .._errors import require
from ._plugins import add_plugin_argument, load_plugins


def add_common(parser):
    add_plugin_argument(parser)
    parser.add_argument("measurement", metavar="MEAS", help="measurement file (reference §3): .npz, long or wide .csv, netCDF / HDF5 (.nc, .h5)")
    parser.add_argument("--weights", help="weights .npz (W1..WL, b1..bL) for a file that holds none (CSV, netCDF)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the held-out split, the model shots and the fit")
    parser.add_argument("--shots", type=int, default=None, help="model shots per input (default: the measured r)")
    parser.add_argument("--figures", default=None, metavar="DIR",
                        help="folder for the figures (default without --json: MEAS_gift/; with --json: none)")


def load(args):
    """Load the plugins (a bad one stops here, before any work), then the measurement file."""
    from ..lab import load_measurement

    load_plugins(args)
    require(args.shots is None or args.shots >= 2, f"--shots {args.shots}: needs at least 2")
    return load_measurement(args.measurement, weights=args.weights)


def key(args):
    return jax.random.PRNGKey(args.seed)


def figure_dir(args):
    if args.figures:
        return args.figures
    if args.json:
        return None
    stem = os.path.splitext(args.measurement)[0]
    return stem + "_gift"
