"""``--plugin FILE.py``: effects a user adds (CONTRACTS §2b), for simulate, compare, diagnose and fit.

Every such command also loads the entry-point group ``gift.effects`` (installed packages that
ship effects). A plugin that fails to import or breaks the contract is a bad input: one line
naming the file and the rule, exit status 2.
"""

from __future__ import annotations


def add_plugin_argument(parser) -> None:
    parser.add_argument("--plugin", action="append", default=[], metavar="FILE.py",
                        help="a Python file that registers effects (CONTRACTS §2b), repeatable; "
                             "installed packages' entry points 'gift.effects' load too")


def load_plugins(args) -> list[str]:
    """Load the entry points, then every ``--plugin`` file; the names they registered."""
    from ..effects import load_entry_points, load_plugin

    names = load_entry_points()
    for path in getattr(args, "plugin", None) or []:
        names += load_plugin(path)
    return names
