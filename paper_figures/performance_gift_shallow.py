"""fig:performance_gift_shallow -- GIFT on the shallower network, training data.

Paper caption: "Percentage improvements in loss (MSE) and accuracy achieved with GIFT
(Algorithm 1) compared to the baseline (no fine-tuning) for the shallower network, under
varying training (s0) and true (st) noise standard deviations."

Data: sweep ``gift_awgn_shallow``. Quick scale: digits, 64-32-32-10; paper scale: mnist5k,
784-500-100-100-10. Run: ``python -m paper_figures.performance_gift_shallow --scale quick``.
"""

from ._plot import improvement_heatmaps

NAME = "performance_gift_shallow"
LABEL = "fig:performance_gift_shallow"
SWEEPS = ("gift_awgn_shallow",)


def draw(data: dict):
    return improvement_heatmaps(data["gift_awgn_shallow"], "train", "pct",
                                "fig:performance_gift_shallow -- GIFT vs no fine-tuning, shallower net, training data")


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
