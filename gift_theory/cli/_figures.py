"""``gift figures [--scale quick|paper] [--only NAME] [--scheduler ADDRESS] [--mnist-folder DIR]``.

Runs the sweeps behind the paper's figures (resumable: a killed run continues where it
stopped) and draws every figure from the saved data. The JSON object: ``scale``, ``seconds``,
``sweeps`` (points done/total, seconds per point), ``figures`` (label, path, status) and
``claims`` (the paper's claims against our numbers). Exit 1 if a figure could not be drawn.
"""

from __future__ import annotations


def add_arguments(parser) -> None:
    from paper_figures._build import add_arguments as add

    add(parser)


def run(args):
    from paper_figures._build import failed, run_args

    from ._main import emit

    result = run_args(args)
    if failed(result):
        emit(result, args.json, render)
        return 1
    return result


def render(result) -> str:
    from paper_figures._build import render as r

    return r(result)
