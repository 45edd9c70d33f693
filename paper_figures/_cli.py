"""``gift figures`` (registered by paper_figures) ``[--scale quick|paper] [--only NAME] [--scheduler ADDRESS] [--data-folder DIR]``.

Runs the sweeps behind the paper's figures (resumable: a killed run continues where it
stopped) and draws every figure from the saved data. The JSON object: ``scale``, ``seconds``,
``sweeps`` (points done/total, seconds per point), ``figures`` (label, path, status) and
``claims`` (the paper's claims against our numbers). Exit 1 if a figure could not be drawn.
"""

from __future__ import annotations

#: the one-line help ``gift --help`` lists (registered through the entry-point group
#: ``gift.commands`` in pyproject.toml, so gift_theory never imports this package)
HELP = "regenerate the paper's figures (sweeps, then drawing)"


def add_arguments(parser) -> None:
    from ._build import add_arguments as add

    add(parser)


def run(args):
    from gift_theory.cli import emit

    from ._build import failed, run_args

    result = run_args(args)
    if failed(result):
        emit(result, args.json, render)
        return 1
    return result


def render(result) -> str:
    from ._build import render as r

    return r(result)
