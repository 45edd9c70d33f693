"""Ours: the bound regions of the linear case (paper Example 1, "Values of alpha for which
eq. cond_for_improvement holds", Figure at line ~1613 of the paper).

Drawn from ``linear_case``'s public functions; while they do not exist, the script raises a
clear "needs ..." error. Run: ``python -m paper_figures.bound_region``.
"""

from ._linear import linear_api

NAME = "bound_region"
LABEL = "ours:bound_region"
SWEEPS = ()


def compute(scale, data_dir: str) -> None:
    linear_api("bound_region")(scale, data_dir)


def draw(data: dict):
    return linear_api("draw_bound_region")(data)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
