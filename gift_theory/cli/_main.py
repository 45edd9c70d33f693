"""``gift``: the console entry point (docs/reference.md §4).

Each subcommand lives in its own module -- the core's in ``gift_theory.cli._<name>``
(:data:`COMMANDS`), those of the packages on top registered through the entry-point group
``gift.commands`` (``check``: proofs_checks, ``figures``: paper_figures) -- with two functions::

    add_arguments(parser)      # add the subcommand's options to an argparse parser
    run(args) -> dict | int    # do the work; return the JSON object (or an exit code)

an optional ``render(result) -> str`` for the human-readable form and, for a registered
module, its one-line ``HELP``. Only the module of the command that runs is imported, so
``gift --help`` stays fast. Every subcommand takes ``--json``: one JSON object on stdout and
nothing else there; progress goes to stderr. Exit status: 0 done, 1 the work failed, 2 bad
input -- one line, no traceback, with "did you mean" for a near miss.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import sys

from .._errors import GiftInputError

#: the core's subcommands -> (module, one-line help); packages on top register theirs through
#: the entry-point group ``gift.commands`` (:func:`commands`)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("gift_theory.cli._demo", "the main job: train, fine-tune with GIFT and its rivals, print a table, draw a figure"),
    "train": ("gift_theory.cli._train", "train an ONN in silico at noise level s0 (cached)"),
    "finetune": ("gift_theory.cli._finetune", "fine-tune trained weights against a simulated chip (GIFT and rivals)"),
    "bench": ("gift_theory.cli._bench", "benchmarks: estimator speed against the machine's matmul rate"),
    "simulate": ("gift_theory.cli._simulate", "write a measurement file from a simulated chip"),
    "compare": ("gift_theory.cli._compare", "compare a model with a measurement file"),
    "diagnose": ("gift_theory.cli._diagnose", "find the physical effect the model is missing"),
    "fit": ("gift_theory.cli._fit", "add effects to the model, fit them, report the error before and after"),
    "design": ("gift_theory.cli._design", "the next measurement that would tell the models left standing apart"),
    "calibrate": ("gift_theory.cli._calibrate", "corrected weights for a chip from a measurement of the programmed ones"),
    "import": ("gift_theory.cli._import", "convert a measurement file (npz, long or wide CSV, netCDF/HDF5) to npz, netCDF or CSV"),
    "export": ("gift_theory.cli._import", "the same as import: write a measurement file as netCDF (.nc), wide CSV or npz"),
}

#: the entry-point group through which other packages add commands (proofs_checks: check,
#: paper_figures: figures; see pyproject.toml)
GROUP = "gift.commands"


def registered() -> dict[str, str]:
    """Commands other packages register: name -> module (entry-point group :data:`GROUP`)."""
    from importlib.metadata import entry_points

    return {ep.name: ep.value.split(":")[0] for ep in entry_points(group=GROUP) if ep.name not in COMMANDS}


def commands() -> dict[str, str]:
    """Every command: name -> module, the core's first."""
    return {name: mod for name, (mod, _) in COMMANDS.items()} | registered()


def command_module(name: str):
    """The module of command ``name`` (None when no installed package provides it)."""
    mod = commands().get(name)
    return None if mod is None else importlib.import_module(mod)


def _help_line(name: str, module_name: str) -> str:
    """The command's one-line help; a registered module's ``HELP`` is read from its source
    (importing the package would make ``gift --help`` wait for jax and sympy)."""
    if name in COMMANDS:
        return COMMANDS[name][1]
    import ast
    import importlib.util

    try:
        top, _, rest = module_name.partition(".")
        spec = importlib.util.find_spec(top)   # a top-level spec imports nothing
        folder = (spec.submodule_search_locations or [os.path.dirname(spec.origin)])[0]
        path = os.path.join(folder, *rest.split(".")) + ".py" if rest else spec.origin
        with open(path, encoding="utf-8") as fh:
            tree = ast.parse(fh.read())
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "HELP" for t in node.targets):
                return ast.literal_eval(node.value)
    except Exception:  # a broken add-on must not break gift --help
        pass
    return f"(from {module_name})"


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad argument as one line and exit status 2, and whose help
    points to the reference page in the repository (section numbers as there)."""

    def error(self, message):
        raise GiftInputError(f"{self.prog}: {message}")

    def format_help(self):
        from ._common import REFERENCE

        return super().format_help().replace("reference §", "reference §").rstrip("\n") + (
            f"\n\nreference: {REFERENCE} (file formats, JSON outputs, effects, mechanism classes)\n")


def _jsonable(obj):
    """Plain JSON types; NaN/inf become null (JSON has no NaN)."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.generic,)):
        obj = obj.item()
    if hasattr(obj, "shape") and hasattr(obj, "tolist"):
        return _jsonable(np.asarray(obj).tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def emit(result, as_json: bool, render=None) -> None:
    """Print ``result``: one JSON object on stdout, or its human form."""
    if as_json:
        sys.stdout.write(json.dumps(_jsonable(result)) + "\n")
    elif render is not None:
        sys.stdout.write(render(result).rstrip("\n") + "\n")
    else:
        sys.stdout.write(json.dumps(_jsonable(result), indent=2) + "\n")
    sys.stdout.flush()


def _top_help() -> str:
    cmds = commands()
    width = max(len(n) for n in cmds)
    lines = ["usage: gift COMMAND [options]   (gift COMMAND --help for a command's options)", "",
             "Verify, reproduce and use GIFT (in situ fine-tuning of in silico trained ONNs).", "", "commands:"]
    lines += [f"  {n:<{width}}  {_help_line(n, m)}" for n, m in cmds.items()]
    lines += ["", "An effect is NAME=VALUE (shot=0.01), NAME=V1,V2 (quantization=6,1.0) or NAME (laplace); the built-in names",
              "(plugins add their own, --plugin FILE.py):", "  " + ", ".join(_effect_names()),
              "", "Exit status: 0 done, 1 the work failed, 2 bad input (one line, no traceback).",
              "Reference (file formats, JSON outputs, effects, mechanism classes): docs/reference.md in the gift repository;",
              "tutorials: docs/notebooks/, docs/lab.md, docs/plugins.md, docs/theory.md."]
    return "\n".join(lines) + "\n"


def _effect_names():
    from ..effects import BUILTIN

    return BUILTIN


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = os.environ.get("GIFT_DEBUG") == "1"
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(_top_help())
        return 0
    if argv[0] == "--version":
        from .. import __version__
        sys.stdout.write(f"gift {__version__}\n")
        return 0
    name = argv[0]
    from .._process import fewer_malloc_arenas
    from .._xla import use_compilation_cache

    fewer_malloc_arenas()  # the work's freed temporaries go back to fewer pools: a lower peak

    use_compilation_cache()  # compiled programs persist on disk across gift runs (GIFT_COMPILATION_CACHE=off: not)
    try:
        cmds = commands()
        if name not in cmds:
            raise GiftInputError(f"gift: unknown command {name!r}; commands: {', '.join(cmds)}")
        module = importlib.import_module(cmds[name])
        help_text = _help_line(name, cmds[name])
        parser = _Parser(prog=f"gift {name}", description=help_text)
        parser.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")
        module.add_arguments(parser)
        args = parser.parse_args(argv[1:])
        result = module.run(args)
        if isinstance(result, int):
            return result
        emit(result, args.json, getattr(module, "render", None))
        return 0
    except GiftInputError as exc:
        from ._common import did_you_mean

        sys.stderr.write(f"{did_you_mean(str(exc))}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("gift: interrupted\n")
        return 130
    except Exception as exc:  # the work failed: one line unless debugging
        from ._plugins import plugin_failure

        line = plugin_failure(exc)  # a plugin's own code raised: a bad input (reference §2b)
        if line is not None and not debug:
            sys.stderr.write(line + "\n")
            return 2
        if debug:
            raise
        sys.stderr.write(f"gift {name}: failed: {type(exc).__name__}: {exc} (GIFT_DEBUG=1 shows the traceback)\n")
        return 1


if __name__ == "__main__":
    raise SystemExit(main())


def entry(argv=None):
    """The ``gift`` console script: :func:`main`, then -- run as the program (``argv`` None) --
    exit without the interpreter's teardown. Called with ``argv`` (a study running commands in
    its own process), it returns main's exit status like :func:`main`.

    JAX's exit hook clears every cache of the programs it compiled (0.7 s after a diagnosis of
    a 16-32-16-8 file, a tenth of the command); the command has nothing left to clean by then
    -- its files are written and closed, its thread pools joined -- so the process leaves
    directly, its output flushed. With child processes still alive, the normal exit runs.
    """
    import multiprocessing

    if argv is not None:
        return main(argv)
    code = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (BrokenPipeError, ValueError):  # the reader is gone or the stream closed: nothing to lose
        pass
    if multiprocessing.active_children():
        sys.exit(code)
    os._exit(code)

