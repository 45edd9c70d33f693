"""fig:performance_gift_shallow -- GIFT on the shallower network, training data.

Paper caption: "Percentage improvements in loss (MSE) and accuracy achieved with GIFT
(Algorithm 1) compared to the baseline (no fine-tuning) for the shallower network, under
varying training (s0) and true (st) noise standard deviations."

Data: sweep ``gift_awgn_shallow``. Quick scale: digits, 64-32-32-10; paper scale: mnist5k,
784-500-100-100-10. Run: ``python -m paper_figures.performance_gift_shallow --scale quick``.
"""

from ._plot import cell_notes, improvement_heatmaps, retrain_oracle

NAME = "performance_gift_shallow"
LABEL = "fig:performance_gift_shallow"
SWEEPS = ("gift_awgn_shallow",)
#: the retrain oracle, where it ran and is saved (cell labels; computed by other figures)
OPTIONAL = ("rivals",)


def draw(data: dict, ax=None):
    notes = cell_notes(data["gift_awgn_shallow"], "train", retrain_oracle(data, "shallow"))
    return improvement_heatmaps(data["gift_awgn_shallow"], "train", "pct",
                                "fig:performance_gift_shallow -- GIFT vs no fine-tuning, shallower net, training data",
                                notes=notes, ax=ax)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
