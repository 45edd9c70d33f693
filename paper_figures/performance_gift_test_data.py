"""fig:performance_gift_test_data -- the same fine-tuned weights on unseen test data.

Paper caption: "Percentage improvements in loss and accuracy achieved by GIFT (Algorithm 1)
compared to baseline (no fine-tuning) for the deeper network on unseen test data under
varying noise standard deviations."

Data: sweep ``gift_awgn_deep`` (the weights of fig:performance_gift), test split keys
``test_loss_*``/``test_accuracy_*``. Run: ``python -m paper_figures.performance_gift_test_data``.
"""

from ._plot import cell_notes, improvement_heatmaps, retrain_oracle

NAME = "performance_gift_test_data"
LABEL = "fig:performance_gift_test_data"
SWEEPS = ("gift_awgn_deep",)
#: the retrain oracle, where it ran and is saved (cell labels; computed by other figures)
OPTIONAL = ("variants", "rivals_regime")


def draw(data: dict, ax=None):
    """The two heatmaps on test data; cells also name the baseline (w0) and, where it ran, the
    retrain oracle's test accuracy. ``ax``: two axes."""
    notes = cell_notes(data["gift_awgn_deep"], "test", retrain_oracle(data, "deep"))
    return improvement_heatmaps(data["gift_awgn_deep"], "test", "pct",
                                "fig:performance_gift_test_data -- GIFT vs no fine-tuning, deeper net, unseen test data",
                                notes=notes, ax=ax)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
