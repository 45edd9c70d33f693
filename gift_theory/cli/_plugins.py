"""``--plugin FILE.py``: effects a user adds (reference §2b), for simulate, compare, diagnose and fit.

Every such command also loads the entry-point group ``gift.effects`` (installed packages that
ship effects). A plugin that fails to import or breaks the contract is a bad input: one line
naming the file and the rule, exit status 2.
"""

from __future__ import annotations


def add_plugin_argument(parser) -> None:
    parser.add_argument("--plugin", action="append", default=[], metavar="FILE.py",
                        help="a Python file that registers effects (reference §2b), repeatable; "
                             "installed packages' entry points 'gift.effects' load too")


def load_plugins(args) -> list[str]:
    """Load the entry points, then every ``--plugin`` file; the names they registered."""
    from ..effects import load_entry_points, load_plugin

    names = load_entry_points()
    mine = []
    for path in getattr(args, "plugin", None) or []:
        mine += load_plugin(path)
    args.plugin_effects = tuple(mine)  # the effects of the --plugin files (the commands check them against the file)
    return names + mine


def plugin_failure(exc: BaseException) -> str | None:
    """The one line for an exception raised inside a plugin's code while a command runs (a
    class method such as ``search``, ``from_data`` or ``signature``, or any helper the hooks
    call), or None when no frame of the traceback is a plugin's. reference §2b: a plugin that
    raises while running is a bad input -- ``FILE: effect NAME (class C), hook H: raised TYPE: msg``.
    The stage hooks are caught where they are called (:class:`gift_theory.effects.Physics`);
    this catches the rest."""
    from ..effects._base import REGISTRY, _is_builtin
    from ..effects._physics import plugin_failure_line

    plugin_classes = {c for c in REGISTRY.values() if not _is_builtin(c)}
    if not plugin_classes:
        return None
    modules = {c.__module__ for c in plugin_classes}
    found = None
    tb = exc.__traceback__
    while tb is not None:
        frame = tb.tb_frame
        if frame.f_globals.get("__name__") in modules:
            me = frame.f_locals.get("self", frame.f_locals.get("cls"))
            cls = me if isinstance(me, type) else type(me) if me is not None else None
            if cls not in plugin_classes:  # a module-level helper: the first plugin class of its module
                cls = next(c for c in plugin_classes if c.__module__ == frame.f_globals.get("__name__"))
            found = (cls, frame.f_code.co_name)
        tb = tb.tb_next
    if found is None:
        return None
    return plugin_failure_line(found[0], found[1], exc)
