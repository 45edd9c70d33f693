"""``gift design MEAS``: the next measurement that would tell the models left standing apart.

Runs the diagnosis of ``gift diagnose`` on the file and prints its ``next_measurement`` object
alone (reference §8): the design, the models it separates, its predicted power at 0.01 and the
shots it takes -- or null when nothing is left to separate (the data are explained by one
model, or the awgn model fits). ``--out INPUTS.npz`` writes the inputs to send (``x``) with how
to measure them (``shots`` per input, ``taps``, ``order``, ``later``), and the object gains
``"out"``: the path written.
"""

from __future__ import annotations

from ._common import Progress
from ._labargs import add_common, key, load


def add_arguments(parser):
    add_common(parser)
    parser.add_argument("--candidates", default=None,
                        help="comma-separated effects to try (default: every registered effect but awgn)")
    parser.add_argument("--out", default=None, metavar="INPUTS.npz",
                        help="write the inputs to send (x) and how to measure them (shots, taps, order, later)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args):
    import os

    import numpy as np

    from .. import atomic_path
    from .._errors import require
    from ..lab import diagnose
    from ..lab._design import inputs_arrays, public

    if args.out is not None:
        require(args.out.endswith(".npz"), f"--out {args.out}: the inputs are written as .npz")
        folder = os.path.dirname(os.path.abspath(args.out))
        require(os.path.isdir(folder), f"--out {args.out}: no folder {folder}")
    meas = load(args)
    cands = [c.strip() for c in args.candidates.split(",") if c.strip()] if args.candidates else None
    res = diagnose(key(args), meas, candidates=cands, shots=args.shots, verbose=not args.quiet,
                   progress=Progress("gift design: candidates", args.quiet), design=True)
    nxt = res.next_measurement
    if nxt is None:
        return None
    out = public(nxt)
    if args.out is not None:
        with atomic_path(args.out) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **inputs_arrays(nxt))
        out["out"] = args.out
    return out


def render(nxt) -> str:
    if nxt is None:
        return ("nothing left to separate: the data are explained by one model or the awgn model fits, or fewer than "
                "two hypotheses can be simulated (gift diagnose says which)")
    line = (f"next measurement: {nxt['design']} -- separates {' / '.join(nxt['separates'])} with power "
            f"{nxt['power']:.2f} at 0.01")
    if nxt.get("out"):
        line += f"\ninputs to send written to {nxt['out']}"
    return line
