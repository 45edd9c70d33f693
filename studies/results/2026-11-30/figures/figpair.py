"""The figures of one ``gift diagnose`` saved the way of 987fd22 and the way of now, alternately, in
one process (paired: the machine's speed drifts between processes).

    python studies/results/2026-11-30/figures/figpair.py FILE.npz [REPEATS]    # from the repository root

The diagnosis runs once (``--no-design``); its figures are captured before saving. Each repeat
saves all of them twice, CPU seconds each: "before" with ``bbox_inches="tight"``, the moments
panels' legends at matplotlib's "best", the where-figure's cell values in the layout and the ppc
panels' density ticks; "after" as ``save_figures`` now does (none of the four).
"""
import contextlib
import io
import sys
import time

import matplotlib

matplotlib.use("agg")
from matplotlib.ticker import AutoLocator  # noqa: E402

import gift_theory.lab._figure_sets as FS  # noqa: E402

cap = {}


def grab(figs, folder, data=None):
    cap["figs"] = figs
    return []


FS.save_figures = grab
from gift_theory.cli._main import main  # noqa: E402

with contextlib.redirect_stdout(io.StringIO()):
    main(["diagnose", sys.argv[1], "--quiet", "--no-design", "--figures", "/tmp/figpair_unused"])
figs = cap["figs"]
CODES = {1: "upper right", 2: "upper left", 3: "lower left", 4: "lower right"}
corners = {n: [CODES[ax.get_legend()._loc] for ax in f.axes[:2]] for n, f in figs.items() if n.startswith("moments")}


def as_before(name, f, before):
    if name.startswith("moments"):
        for ax, loc in zip(f.axes[:2], corners[name]):
            ax.get_legend().set_loc("best" if before else loc)
    if name == "where.png":
        for ax in f.axes:
            for tx in ax.texts:
                tx.set_in_layout(before)
    if name.startswith("ppc"):
        for ax in f.axes:
            if ax.get_visible() and ax.axison:
                if before:
                    ax.yaxis.set_major_locator(AutoLocator())
                else:
                    ax.set_yticks([])


repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 4
total = {"before": 0.0, "after": 0.0}
for rep in range(repeats):
    for v in ("before", "after"):
        t0 = time.process_time()
        for name, f in figs.items():
            as_before(name, f, v == "before")
            f.savefig(io.BytesIO(), format="png", dpi=120, bbox_inches="tight" if v == "before" else None)
        dt = time.process_time() - t0
        total[v] += dt
        print(rep, v, round(dt, 2), flush=True)
print({k: round(x / repeats, 2) for k, x in total.items()}, "CPU s per set of", len(figs), "figures")
