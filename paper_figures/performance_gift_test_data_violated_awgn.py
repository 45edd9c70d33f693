"""fig:performance_gift_test_data_violated_awgn -- unseen test data, multiplicative true noise.

Paper caption: "Percentage improvements in loss and accuracy achieved [by] Algorithm 1 compared
to baseline (no fine-tuning) for the deeper network on unseen test data under a violated AWGN
assumption (multiplicative noise). Confidence intervals are set at 95%."

Data: sweep ``gift_violated`` at noise_kind = multiplicative (m = st, additive awgn off), test
split. Run: ``python -m paper_figures.performance_gift_test_data_violated_awgn``.
"""

from .performance_gift_violated_noise_assumption import draw_split

NAME = "performance_gift_test_data_violated_awgn"
LABEL = "fig:performance_gift_test_data_violated_awgn"
SWEEPS = ("gift_violated",)


def draw(data: dict):
    return draw_split(data["gift_violated"], "test", ("multiplicative",),
                      "fig:performance_gift_test_data_violated_awgn -- deeper net,\nunseen test data, "
                      "multiplicative noise")


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
