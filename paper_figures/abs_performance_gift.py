"""fig:abs_performance_gift -- absolute instead of relative improvements (appendix).

Paper caption: "Mean loss and accuracy improvements achieved with GIFT (Algorithm 1) compared
to baseline performance without fine-tuning. Results are shown for the deeper network under
varying noise standard deviations."

Data: sweep ``gift_awgn_deep``; loss improvement L_before - L_after (MSE units), accuracy
improvement A_after - A_before in percentage points. Run:
``python -m paper_figures.abs_performance_gift``.
"""

from ._plot import improvement_heatmaps

NAME = "abs_performance_gift"
LABEL = "fig:abs_performance_gift"
SWEEPS = ("gift_awgn_deep",)


def draw(data: dict, ax=None):
    """``ax``: two axes to draw into (default a new figure)."""
    return improvement_heatmaps(data["gift_awgn_deep"], "train", "abs",
                                "fig:abs_performance_gift -- absolute improvements, deeper net, training data", ax=ax)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
