"""Arguments shared by ``gift compare``, ``gift diagnose`` and ``gift fit``."""

from __future__ import annotations

import os

import jax

from .._errors import require
from ._plugins import add_plugin_argument, load_plugins


def add_common(parser):
    add_plugin_argument(parser)
    parser.add_argument("measurement", metavar="MEAS", help="measurement file (reference §3): .npz, long or wide .csv, netCDF / HDF5 (.nc, .h5)")
    parser.add_argument("--weights", help="weights .npz (W1..WL, b1..bL) for a file that holds none (CSV, netCDF); "
                                          "default: MEAS-stem.weights.npz beside it, when it exists")
    parser.add_argument("--seed", type=int, default=0, help="seed of the held-out split, the model shots and the fit")
    parser.add_argument("--shots", type=int, default=None, help="model shots per input (default: the measured r)")
    parser.add_argument("--figures", default=None, metavar="DIR",
                        help="folder for this command's figures, each PNG with its numbers as netCDF beside it "
                             "(default without --json: MEAS_gift/COMMAND/; with --json: none); a folder holding "
                             "another command's figures is refused")


#: inputs a command needs: a fit on half of them and a held-out test over the other half
#: (compare --effect scores every input: the test over inputs needs 3)
MIN_INPUTS_FITTED, MIN_INPUTS_SCORED = 4, 3


def load(args, min_inputs: int = MIN_INPUTS_FITTED):
    """Load the plugins (a bad one stops here, before any work), then the measurement file,
    refusing one with fewer than ``min_inputs`` inputs (one line naming the file)."""
    from ..effects import REGISTRY
    from ..effects._physics import scope_error
    from ..lab import load_measurement

    load_plugins(args)
    require(args.shots is None or args.shots >= 2, f"--shots {args.shots}: needs at least 2")
    meas = load_measurement(args.measurement, weights=weights_of(args))
    for name in getattr(args, "plugin_effects", ()):  # a plugin given for this file must act on it
        err = scope_error(REGISTRY[name], meas.arch.depth)
        require(err is None, f"--plugin: {err}")
    require(meas.n >= min_inputs, f"{args.measurement}: has {meas.n} input(s); "
            + ("fitting on half the inputs and testing on the other half needs at least 4"
               if min_inputs == MIN_INPUTS_FITTED else f"the test over inputs needs at least {min_inputs}"))
    require(meas.r >= 4, f"{args.measurement}: has {meas.r} shots per input; the noise floor (random halves of the "
                         f"shots) needs at least 4")
    return meas


def weights_of(args, measurement: str | None = None):
    """``--weights``, else the ``STEM.weights.npz`` that ``gift simulate --csv`` and ``gift import``
    write beside a file without weights (a CSV), when it exists (said on stderr), else None.
    ``measurement``: the file's path (default ``args.measurement``)."""
    if args.weights:
        return args.weights
    measurement = args.measurement if measurement is None else measurement
    stem, ext = os.path.splitext(measurement)
    beside = stem + ".weights.npz"
    if ext.lower() != ".npz" and os.path.exists(beside):
        import sys

        print(f"weights from {beside} (written beside {os.path.basename(measurement)}; --weights overrides)",
              file=sys.stderr)
        return beside
    return None


def key(args):
    return jax.random.PRNGKey(args.seed)


def figure_processes(folder: str | None) -> int:
    """The processes a command draws its figures in (:func:`gift_theory.lab.save_figures`; the
    files are the same either way): 1 without a figure folder, else ``$GIFT_FIGURE_PROCESSES``
    (1 or 2; another value is a bad input), default 2 when this process may use two cores or
    more. With 2 the helper process is started now, so that its start-up overlaps the command's
    computation."""
    env = os.environ.get("GIFT_FIGURE_PROCESSES", "").strip()
    require(env in ("", "1", "2"), f"GIFT_FIGURE_PROCESSES={env}: needs 1 or 2")
    if not folder:
        return 1
    if env:
        n = int(env)
    else:
        from ..lab._budget import usable_cores

        n = 2 if usable_cores() >= 2 else 1
    if n == 2:
        from ..lab._drawing import start_helper

        start_helper()
    return n


#: the file in a figure folder that says which command's figures it holds
MANIFEST = "figures.json"


def figure_dir(args, command: str):
    """The folder ``command``'s figures go to: ``--figures DIR``, else (without ``--json``)
    ``MEAS_gift/COMMAND/``, else None. A folder whose manifest says it holds another command's
    figures is a bad input (checked before any work: one command never overwrites another's)."""
    if args.figures:
        folder = args.figures
    elif args.json:
        return None
    else:
        folder = os.path.join(os.path.splitext(args.measurement)[0] + "_gift", command)
    path = os.path.join(folder, MANIFEST)
    if os.path.exists(path):
        import json

        try:
            with open(path, encoding="utf-8") as fh:
                owner = json.load(fh).get("command")
        except (OSError, ValueError, AttributeError):
            owner = None
        require(owner in (None, command), f"--figures {folder}: holds the figures of gift {owner}; give gift "
                                          f"{command} a folder of its own")
    return folder


def write_manifest(folder: str, command: str, args, figures: list) -> None:
    """Record in ``folder`` which command wrote its figures, from which file (:data:`MANIFEST`)."""
    import json

    from .. import atomic_write_text

    atomic_write_text(os.path.join(folder, MANIFEST), json.dumps(
        {"command": command, "measurement": os.path.abspath(args.measurement),
         "figures": [os.path.basename(f) for f in figures],
         "data": [os.path.splitext(os.path.basename(f))[0] + ".nc" for f in figures
                  if os.path.exists(os.path.splitext(f)[0] + ".nc")]}, indent=1) + "\n")
