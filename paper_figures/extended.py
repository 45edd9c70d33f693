"""Ours: our grid extended where relative gains inflate -- the deeper net at s0 in {0.01, 0.02}
and st in {0.5, 0.6, 0.8}, where w0's accuracy on the chip falls towards chance.

Not a paper figure. One row per method: GIFT, GIFT without its confirmation, Algorithm 1 as
printed with the pathwise direction (``pathwise``), the ceiling of GIFT's line (the referee's
best step along it, chosen on training data), the retrain oracle and identify-retrain (the
chip's noise identified in situ, then retraining). Left: the relative accuracy gain (%),
right: the absolute one (accuracy points), both on training data; each cell the mean over
seeds, ± the 95 % interval, the baseline accuracy under it.
Data: sweeps ``extended`` and ``ceiling_extended``.
Run: ``python -m paper_figures --scale paper --workers 1 --only extended`` (resumable).
"""

from __future__ import annotations

import matplotlib.pyplot as plt

from ._plot import cell_notes, grid_note, heatmap, improvements, mean_ci
from .gain_vs_baseline import ceiling_as_finetune

NAME = "extended"
LABEL = "ours:extended"
# the ceiling first: the cheap, most informative points land before identify-retrain's
SWEEPS = ("ceiling_extended", "extended")

LABELS = {"gift": "GIFT", "gift-noconfirm": "GIFT without confirmation",
          "pathwise": "Algorithm 1, pathwise direction", "ceiling": "ceiling of GIFT's line",
          "retrain": "retrain oracle (knows st)", "identify-retrain": "identify-retrain (in situ)"}


def rows(data: dict) -> list[tuple[str, object]]:
    """(method label, fine-tuning dataset with dims s0, st, seed), the ceiling after pathwise."""
    ext, ceil = data["extended"], data["ceiling_extended"]
    out = []
    for m in [str(v) for v in ext["method"].values]:
        out.append((m, ext.sel({"method": m}, drop=True)))
        if m == "pathwise" and "pathwise_accuracy_best" in ceil:
            out.append(("ceiling", ceiling_as_finetune(ceil, "pathwise")))
    if not any(m == "ceiling" for m, _ in out) and "pathwise_accuracy_best" in ceil:
        out.append(("ceiling", ceiling_as_finetune(ceil, "pathwise")))
    return out


def draw(data: dict, ax=None):
    """One row per method, columns relative (%) and absolute (points) accuracy gain on training
    data. ``ax``: an (n_methods, 2) array of axes. Returns the Figure."""
    rs = rows(data)
    if ax is None:
        fig, axes = plt.subplots(len(rs), 2, figsize=(10, 2.7 * len(rs)), squeeze=False)
    else:
        axes = ax
        fig = axes[0][0].figure
    for i, (m, ds) in enumerate(rs):
        imp = improvements(ds, "train")
        notes = cell_notes(ds, "train")
        for j, (var, unit, what) in enumerate((("acc_pct", "%", "relative, %"),
                                                ("acc_abs", "", "absolute, accuracy points"))):
            mean, half = mean_ci(imp[var])
            heatmap(axes[i][j], mean, half, f"{LABELS.get(m, m)}: accuracy gain {what}", unit=unit, notes=notes)
    fig.suptitle("our grid extended on the deeper net (784-500-250-250-100-50-10): training data, mean over seeds "
                 "± 95 % CI, base = w0's accuracy on the chip\n" + grid_note(data["extended"]), fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
