"""fig:example-fine-tuning -- J_{s0} and J_{st} around their minimisers, from the linear closed forms.

Paper caption: "(Left) Schematic depictions of J_{s0} and J_{st} for some s0 != st. (Right)
The curves around the minimizers of the in situ and ex situ objectives."

Drawn from the closed forms of ``linear_case`` (the paper's Example 1), not a schematic. This
script only calls linear_case's public API; while that package does not provide it, the script
raises a clear "needs ..." error instead of re-deriving the closed forms here.
Run: ``python -m paper_figures.example_fine_tuning``.
"""

from ._linear import linear_api

NAME = "example_fine_tuning"
LABEL = "fig:example-fine-tuning"
SWEEPS = ()


def compute(scale, data_dir: str) -> None:
    api = linear_api("objective_curves")
    api(scale, data_dir)


def draw(data: dict):
    return linear_api("draw_objective_curves")(data)


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
