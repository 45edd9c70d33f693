"""``gift import IN --out OUT`` (also ``gift export``): one measurement campaign from any format
gift reads to any it writes (reference §3).

IN: ``.npz``, long or wide CSV, netCDF / HDF5 (the format told by the content, then the
extension); ``--weights W.npz`` where IN holds none (default: ``IN-stem.weights.npz`` when it
exists, as written beside a CSV). OUT by its extension: ``.npz``,
``.nc`` (or ``.h5``: netCDF-4) or ``.csv`` (wide, or long with ``--long``; the weights then
go to ``OUT-stem.weights.npz``). The input is read and validated completely before anything
is written, and every file is written atomically: a bad input leaves OUT as it was.
"""

from __future__ import annotations

import os


def add_arguments(parser):
    parser.add_argument("input", metavar="IN", help="measurement file: .npz, long or wide .csv, netCDF / HDF5")
    parser.add_argument("--out", required=True, metavar="OUT",
                        help="file to write: .npz, .nc / .h5 (netCDF-4) or .csv (wide; weights to OUT.weights.npz)")
    parser.add_argument("--weights", help="weights .npz (W1..WL, b1..bL) for an IN that holds none (CSV, netCDF)")
    parser.add_argument("--long", action="store_true", help="write a .csv OUT in the long layout (input,shot,layer,neuron,value)")


def run(args):
    from .._errors import require
    from ..lab._io import NETCDF_EXTENSIONS, detect_format, load_measurement, save_file

    ext = os.path.splitext(args.out)[1].lower()
    require(ext in (".npz", ".csv") + NETCDF_EXTENSIONS,
            f"--out {args.out}: unknown extension {ext or '(none)'!r}; write .npz, .csv or netCDF (.nc, .h5)")
    require(not args.long or ext == ".csv", f"--long: only for a .csv OUT, not {args.out}")
    fmt_in = detect_format(args.input)
    from ._labargs import weights_of

    meas = load_measurement(args.input, weights=weights_of(args, args.input))
    wpath = save_file(args.out, meas, csv="long" if args.long else "wide")
    fmt_out = {".npz": "npz", ".csv": "csv-long" if args.long else "csv-wide"}.get(ext, "netcdf")
    return {"in": args.input, "format_in": fmt_in, "out": args.out, "format_out": fmt_out, "weights_out": wpath,
            "n": meas.n, "r": meas.r, "arch": list(meas.arch.widths), "activation": meas.activation,
            "taps": meas.has_taps, "times": meas.t is not None}


def render(out) -> str:
    return (f"read {out['in']} ({out['format_in']}): {out['n']} inputs x {out['r']} shots, arch "
            f"{'-'.join(map(str, out['arch']))} ({out['activation']})" + (", taps" if out["taps"] else "")
            + (", times" if out["times"] else "") + f"\nwrote {out['out']} ({out['format_out']})"
            + (f" and its weights {out['weights_out']}" if out["weights_out"] else ""))
