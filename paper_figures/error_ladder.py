"""Ours: the error ladder of the measurement loop (issue 5): the model-measurement discrepancy
as effects are added and fitted one by one, against the noise floor.

Uses ``gift_theory.lab``'s public error-ladder function; while it does not exist the script
raises a clear "needs ..." error. Run: ``python -m paper_figures.error_ladder``.
"""

from ._jobs import needs

NAME = "error_ladder"
LABEL = "ours:error_ladder"
SWEEPS = ()


def _ladder():
    from gift_theory import lab

    fn = getattr(lab, "error_ladder", None)
    if fn is None:
        raise needs("gift_theory.lab.error_ladder", "the measurement loop's error ladder, issue 5")
    return fn


def compute(scale, data_dir: str) -> None:
    _ladder()
    raise needs("a saved-data format for gift_theory.lab.error_ladder", "not wired yet")


def draw(data: dict):
    _ladder()
    raise needs("a saved-data format for gift_theory.lab.error_ladder", "not wired yet")


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
