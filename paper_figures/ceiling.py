"""Ours: the ceiling of the GIFT line -- the most any search along w0 + a u could give.

Not a paper figure. For every point of the GIFT grid (and the extended st on the deeper net),
the referee scans the line w0 + a u densely on the training data and takes the step of the
highest training accuracy; the panels show the relative accuracy gain of that step on the
test data (so the step is chosen without the test data), for u the pathwise d/ds grad J_s0
(GIFT's direction) and the printed D^[0] (Algorithm 1's), on both nets. Cells: mean over seeds
± 95 % CI, the baseline accuracy; colour: the interval's end nearest 0.
Data: sweeps ``ceiling_deep``, ``ceiling_shallow`` (:func:`paper_figures._jobs.ceiling_job`).
Run: ``python -m paper_figures.ceiling --scale paper``.
"""

from __future__ import annotations

import matplotlib.pyplot as plt

from ._plot import cell_notes, grid_note, heatmap, improvements, mean_ci
from .gain_vs_baseline import ceiling_as_finetune

NAME = "ceiling"
LABEL = "ours:ceiling"
SWEEPS = ("ceiling_deep", "ceiling_shallow")
KINDS = (("pathwise", "GIFT's pathwise direction"), ("score_paper", "the printed D^[0]"))


def draw(data: dict, ax=None):
    """Rows: deeper, shallower net; columns: pathwise, printed direction. ``ax``: a 2 x 2 array
    of axes to draw into. Returns the Figure."""
    if ax is None:
        fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    else:
        axes = ax
        fig = axes[0][0].figure
    notes_line = []
    for i, (name, net) in enumerate((("ceiling_deep", "deeper"), ("ceiling_shallow", "shallower"))):
        ds = data[name]
        notes_line.append(f"{net}: {grid_note(ds)}")
        for j, (kind, what) in enumerate(KINDS):
            a = axes[i][j]
            if f"{kind}_accuracy_best" not in ds:
                a.set_axis_off()
                a.set_title(f"{net} net, {what}: not computed", fontsize=9)
                continue
            ft = ceiling_as_finetune(ds, kind)
            m, h = mean_ci(improvements(ft, "test")["acc_pct"])
            heatmap(a, m, h, f"{net} net: best step along {what}\n(chosen on training data), test accuracy gain, %",
                    notes=cell_notes(ft, "test"))
    fig.suptitle("the ceiling of the GIFT line: the referee's best step, chosen on training data, reported on test "
                 "data; mean over seeds ± 95 % CI\n" + "; ".join(notes_line), fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
