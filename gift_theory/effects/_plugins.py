"""Loading effects a user adds (reference §2b): a Python file, or the entry-point group
``gift.effects``.

A plugin file is imported under a module name of its own (derived from its resolved path,
so two files of the same name do not collide) and registers its effects with
:func:`~gift_theory.effects.register`. Whatever goes wrong -- no file, a syntax error, an
exception on import, no effect registered, a class that breaks a rule of the contract --
is a bad input: :class:`~gift_theory.GiftInputError` with one line ``PATH: what is wrong``.
A failed load leaves :data:`~gift_theory.effects.REGISTRY` as it was.

Loading a path again is harmless: an unchanged file is not re-executed and gives the same
names; a changed file is re-executed and its classes replace their earlier versions.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.metadata
import importlib.util
import os
import re
import sys
import traceback
import types

from .._errors import GiftInputError
from ._base import REGISTRY, Effect, register

#: resolved path -> ((mtime_ns, size), names) of the files loaded so far
_LOADED: dict[str, tuple[tuple[int, int], list[str]]] = {}

#: entry-point value -> names registered by it
_LOADED_EP: dict[str, list[str]] = {}


def _module_name(real: str) -> str:
    stem = re.sub(r"\W", "_", os.path.splitext(os.path.basename(real))[0]) or "plugin"
    digest = hashlib.sha1(real.encode()).hexdigest()[:12]
    return f"gift_plugin_{stem}_{digest}"


def _plugin_line(exc: BaseException, real: str) -> str:
    """`` (line N)`` for the deepest frame of the traceback inside the plugin file."""
    line = None
    for frame in traceback.extract_tb(exc.__traceback__):
        if os.path.realpath(frame.filename) == real:
            line = frame.lineno
    return f"line {line}: " if line else ""


def _names_since(before: dict) -> list[str]:
    """Effect names registered (or re-registered by another class) since the snapshot."""
    return [n for n, c in REGISTRY.items() if before.get(n) is not c]


def _restore(before: dict) -> None:
    REGISTRY.clear()
    REGISTRY.update(before)


def load_plugin(path) -> list[str]:
    """Import the plugin file ``path`` and return the names of the effects it registered.

    Parameters
    ----------
    path : str or os.PathLike
        A Python file whose classes use ``@register`` (reference §2b).

    Returns
    -------
    list of str
        The effect names the file registered, in registration order. Loading the same
        unchanged file again returns the same names.

    Raises
    ------
    GiftInputError
        ``"PATH: <what is wrong>"`` (one line) when the file does not exist, does not parse,
        raises on import, registers no effect, or defines an effect that breaks a rule of
        :func:`~gift_theory.effects.register`. Nothing stays registered then.
    """
    shown = os.fspath(path)
    real = os.path.realpath(shown)
    if not os.path.exists(real):
        raise GiftInputError(f"{shown}: no such file")
    if not os.path.isfile(real):
        raise GiftInputError(f"{shown}: not a file")
    try:
        st = os.stat(real)
        with open(real, "rb") as fh:
            source = fh.read()
    except OSError as exc:
        raise GiftInputError(f"{shown}: cannot read it ({exc.strerror or exc})") from None
    stamp = (st.st_mtime_ns, st.st_size)
    done = _LOADED.get(real)
    if done is not None and done[0] == stamp and all(n in REGISTRY for n in done[1]):
        return list(done[1])
    try:
        code = compile(source, real, "exec")
    except SyntaxError as exc:
        where = f"line {exc.lineno}: " if exc.lineno else ""
        raise GiftInputError(f"{shown}: {where}{exc.msg}") from None
    except ValueError as exc:  # e.g. null bytes
        raise GiftInputError(f"{shown}: not Python source ({exc})") from None
    modname = _module_name(real)
    loader = importlib.machinery.SourceFileLoader(modname, real)
    spec = importlib.util.spec_from_file_location(modname, real, loader=loader)
    module = importlib.util.module_from_spec(spec)
    before = dict(REGISTRY)
    previous = sys.modules.get(modname)
    sys.modules[modname] = module  # dataclasses look the module up while processing a class
    try:
        exec(code, module.__dict__)
    except GiftInputError as exc:
        _restore(before)
        _drop(modname, previous)
        raise GiftInputError(f"{shown}: {exc}") from None
    except (Exception, SystemExit) as exc:  # a plugin's own error: report it, never crash
        _restore(before)
        _drop(modname, previous)
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GiftInputError(f"{shown}: {_plugin_line(exc, real)}importing it raised "
                             f"{type(exc).__name__}{': ' + msg if msg else ''}") from None
    names = _names_since(before)
    if not names and done is not None:
        names = [n for n in done[1] if n in REGISTRY]
    if not names:
        _restore(before)
        _drop(modname, previous)
        raise GiftInputError(f"{shown}: registers no effect (decorate a subclass of "
                             f"gift_theory.effects.Effect with @register)")
    _LOADED[real] = (stamp, names)
    return list(names)


def _drop(modname: str, previous) -> None:
    if previous is None:
        sys.modules.pop(modname, None)
    else:
        sys.modules[modname] = previous


def load_entry_points(group: str = "gift.effects") -> list[str]:
    """Load every entry point of ``group`` and return the effect names they provide.

    An entry point names a module (importing it registers its effects) or an
    :class:`~gift_theory.effects.Effect` subclass (registered if it is not yet). Loading
    twice is harmless.

    Raises
    ------
    GiftInputError
        ``"entry point NAME (VALUE): <what is wrong>"`` for an entry point that fails to
        load, provides no effect or breaks a rule of :func:`~gift_theory.effects.register`;
        the effects of that entry point are not left registered.
    """
    out: list[str] = []
    for ep in importlib.metadata.entry_points(group=group):
        for n in load_entry_point(ep):
            if n not in out:
                out.append(n)
    return out


def load_entry_point(ep) -> list[str]:
    """Load one entry point (an ``importlib.metadata.EntryPoint``); see :func:`load_entry_points`."""
    shown = f"entry point {ep.name} ({ep.value})"
    if ep.value in _LOADED_EP and all(n in REGISTRY for n in _LOADED_EP[ep.value]):
        return list(_LOADED_EP[ep.value])
    before = dict(REGISTRY)
    try:
        obj = ep.load()
        if isinstance(obj, type):
            if not issubclass(obj, Effect):
                raise GiftInputError(f"{obj.__name__} is not a subclass of gift_theory.effects.Effect")
            obj = register(obj)
            names = [obj.name]
        elif isinstance(obj, types.ModuleType):
            names = _names_since(before) or [n for n, c in REGISTRY.items() if c.__module__ == obj.__name__]
            if not names:
                raise GiftInputError("registers no effect (decorate a subclass of gift_theory.effects.Effect "
                                     "with @register)")
        else:
            raise GiftInputError(f"names a {type(obj).__name__}; it must name a module or an Effect subclass")
    except GiftInputError as exc:
        _restore(before)
        raise GiftInputError(f"{shown}: {exc}") from None
    except (Exception, SystemExit) as exc:
        _restore(before)
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GiftInputError(f"{shown}: loading it raised {type(exc).__name__}{': ' + msg if msg else ''}") from None
    _LOADED_EP[ep.value] = names
    return list(names)
