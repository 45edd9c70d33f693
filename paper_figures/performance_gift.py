"""fig:performance_gift -- GIFT on the deeper network, training data.

Paper caption: "Percentage improvements in loss (MSE) and accuracy achieved with GIFT
(Algorithm 1) compared to the baseline (no fine-tuning) for the deeper NN, under varying
training (s0) and true (st) noise standard deviations."

Data: sweep ``gift_awgn_deep`` (dims s0, st, seed; the chip's true noise is AWGN with level
st). Quick scale: digits, 64-48-32-32-16-10; paper scale: mnist5k, 784-500-250-250-100-50-10.
Run: ``python -m paper_figures.performance_gift --scale quick``.
"""

from ._plot import cell_notes, improvement_heatmaps, retrain_oracle

NAME = "performance_gift"
LABEL = "fig:performance_gift"
SWEEPS = ("gift_awgn_deep",)
#: the retrain oracle, where it ran and is saved (cell labels; computed by other figures)
OPTIONAL = ("variants", "rivals_regime")


def draw(data: dict, ax=None):
    """Heatmaps of mean relative loss and accuracy improvement over (s0, st); each cell also names
    its baseline (w0) accuracy and, where it ran, the retrain oracle's. ``ax``: two axes."""
    notes = cell_notes(data["gift_awgn_deep"], "train", retrain_oracle(data, "deep"))
    return improvement_heatmaps(data["gift_awgn_deep"], "train", "pct",
                                "fig:performance_gift -- GIFT vs no fine-tuning, deeper net, training data",
                                notes=notes, ax=ax)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
