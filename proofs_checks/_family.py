"""The user's J_s family (reference §5b): :class:`Family`, :func:`family` from sympy objects or a
JAX-differentiable ``J(w, s)``, and :func:`load_family` from a family file; a family that breaks
the contract raises :class:`FamilyError` (one line). :func:`proofs_checks.theorem1` checks
Theorem 1 on it.
"""

from __future__ import annotations

import os
import runpy
from typing import Any, NamedTuple

import numpy as np

from ._exact import _exact

#: what a family file must define (reference §5b)
FAMILY_NAMES = ("s", "w", "J", "w0")


class Family(NamedTuple):
    """A J_s family. ``kind`` is "sympy" or "numeric"; ``wt`` optional candidate critical points of
    J_st; ``certify`` (numeric, optional) a callable ``(w_flat, s) -> dict(verified, radius, how)``
    or None that proves a degenerate critical point exactly (where Krawczyk's test cannot)."""

    kind: str
    J: Any
    w0: Any
    s: Any = None
    w: tuple = ()
    wt: Any = None
    name: str = "family"
    certify: Any = None


class FamilyError(ValueError):
    """A family that breaks the contract of reference §5b (one line, names the rule)."""

    def __init__(self, message):
        super().__init__(" ".join(str(message).split()))      # one line, whatever the cause's text


def family(J, w0, *, s=None, w=None, wt=None, name: str = "family", certify=None) -> Family:
    """A :class:`Family` from sympy objects (``s``, ``w``, expression ``J``) or from a
    JAX-differentiable ``J(w, s)`` and an array ``w0`` (``certify``: see :class:`Family`)."""
    import sympy as sp

    if isinstance(J, sp.Basic):
        if s is None or w is None:
            raise FamilyError("a sympy family needs the symbol `s` and the weights `w`")
        if not isinstance(s, sp.Symbol):
            raise FamilyError("`s` must be a sympy Symbol")
        ws = tuple(w) if isinstance(w, (list, tuple)) else (w,)
        if not ws or not all(isinstance(x, sp.Symbol) for x in ws):
            raise FamilyError("`w` must be a sympy Symbol or a list of Symbols")
        if s in ws:
            raise FamilyError("`s` must not be one of the weights `w`")
        extra = J.free_symbols - set(ws) - {s}
        if extra:
            raise FamilyError(f"`J` depends on symbols other than s and w: {', '.join(sorted(map(str, extra)))}")
        undef = J.atoms(sp.core.function.AppliedUndef)
        if undef:
            raise FamilyError(f"`J` contains undefined functions: {', '.join(sorted(map(str, undef)))}")
        if J.has(sp.I):
            raise FamilyError("`J` must be real (it contains the imaginary unit I)")
        kinks = [f.__name__ for f in (sp.Abs, sp.sign, sp.Heaviside, sp.Piecewise, sp.Max, sp.Min, sp.floor,
                                      sp.ceiling) if J.has(f)]
        if kinks:
            raise FamilyError(f"`J` must be smooth in s and w (Theorem 1 differentiates it three times); it "
                              f"contains {', '.join(kinks)}")
        w0s = list(w0) if isinstance(w0, (list, tuple)) else [w0]
        if len(w0s) != len(ws):
            raise FamilyError(f"`w0` has {len(w0s)} entries but `w` has {len(ws)}")
        try:
            w0s = tuple(_exact(x) for x in w0s)
        except (TypeError, ValueError, sp.SympifyError):
            raise FamilyError("`w0` must be numbers (or sympy numbers)") from None
        if any(x.free_symbols for x in w0s):
            raise FamilyError("`w0` must be numbers, not expressions with symbols")
        return Family("sympy", J, w0s, s, ws, wt, name)
    if callable(J):
        try:
            w0a = np.asarray(w0, dtype=np.float64)
        except (TypeError, ValueError):
            raise FamilyError("`w0` of a numeric family must be an array of numbers") from None
        if w0a.ndim == 0:
            w0a = w0a.reshape(1)
        wts = None
        if wt is not None:
            try:            # one point of the shape of w0 (e.g. wt = [1.5, 0]), or a list of points
                one = np.asarray(wt, np.float64)
                lst = [wt] if one.size == w0a.size else (list(wt) if isinstance(wt, (list, tuple)) else [wt])
            except (TypeError, ValueError):
                lst = list(wt) if isinstance(wt, (list, tuple)) else [wt]
            try:
                wts = [np.asarray(x, np.float64).reshape(w0a.shape) for x in lst]
            except (TypeError, ValueError):
                raise FamilyError(f"`wt` must be arrays of the shape of w0 {w0a.shape}") from None
        return Family("numeric", J, w0a, None, (), wts, name, certify)
    raise FamilyError("`J` must be a sympy expression in s and w, or a callable J(w, s)")


def load_family(path: str) -> Family:
    """Load a family file (reference §5b); a broken file raises :class:`FamilyError`."""
    if not os.path.isfile(path):
        raise FamilyError(f"{path}: no such file")
    try:
        ns = runpy.run_path(path, run_name="gift_family")
    except (Exception, SystemExit) as exc:  # the user's file failed to run (or called exit)
        raise FamilyError(f"{path}: failed to run: {type(exc).__name__}: {exc}") from None
    if "J" not in ns or "w0" not in ns:
        raise FamilyError(f"{path}: must define `J` and `w0` (and `s`, `w` for a sympy family)")
    try:
        return family(ns["J"], ns["w0"], s=ns.get("s"), w=ns.get("w"), wt=ns.get("wt"),
                      name=os.path.basename(path), certify=ns.get("certify"))
    except FamilyError as exc:
        raise FamilyError(f"{path}: {exc}") from None
