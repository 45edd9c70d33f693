"""The helper process of :class:`._drawing.Drawing` (``python -m gift_theory.lab._draw_helper``).

Reads drawings from stdin, each a length (8 bytes, little-endian) and a pickled ``(drawing,
path)`` from the process that started it, draws and writes each (:func:`._drawing.draw_to`) and
answers one byte: ``1`` written, ``0`` failed (the caller then draws it itself). Ends at the end of
its input, at once. Its own output goes to stderr, so that nothing but the answers reaches stdout.
"""

from __future__ import annotations

import os
import pickle
import sys


def main() -> int:
    answers = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)  # whatever else writes to stdout, Python or C, goes to stderr
    import matplotlib

    matplotlib.use("agg")
    from ._drawing import draw_to

    _warm_up()
    source = sys.stdin.buffer
    while True:
        head = source.read(8)
        if len(head) < 8:  # every file is written (and synced): end without the interpreter's tear-down
            sys.stderr.flush()  # (half a second with JAX loaded, which the caller would wait for)
            os._exit(0)
        payload = source.read(int.from_bytes(head, "little"))
        try:
            draw_to(*pickle.loads(payload))
            answers.write(b"1")
        except Exception:  # the caller draws it again, where the error is raised
            answers.write(b"0")


def _warm_up() -> None:
    """Draw a small figure with what the lab's figures use (a constrained layout, mathtext, log
    axes, a legend), and import the netCDF writer, while the command computes: the fonts, the
    parsers and xarray are then loaded before the first real drawing or numbers arrive."""
    import io

    import h5netcdf  # noqa: F401
    import xarray  # noqa: F401

    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2), layout="constrained")
    ax = fig.add_subplot()
    ax.plot([1, 10], [1, 10], label="$\\pm$ 2 se")
    ax.set_xscale("log")
    ax.set_title("warm-up")
    ax.legend()
    fig.savefig(io.BytesIO(), format="png", dpi=30)


if __name__ == "__main__":
    sys.exit(main())
