"""Nothing non-finite goes on silently: the checks between the stages of a computation.

gift computes in float32. A value that float32 cannot hold -- a measurement beyond its range,
an overflow inside a forward pass, a plugin hook that returns NaN -- must stop the work where
it appears, never be dropped by a statistic further on. Two outcomes:

* a **bad input** (:class:`~gift_theory.GiftInputError`, exit 2): the file (checked by its
  loader in float32) or a plugin's hook (named with its file and effect; found by running
  the stage again eagerly, where every hook's result is checked as it is returned);
* a **failed run** (:class:`NotFinite`, exit 1): the computation itself overflowed; the
  message says which stage and what was being computed.
"""

from __future__ import annotations

import numpy as np


class NotFinite(ArithmeticError):
    """The work failed: a stage produced a value float32 cannot hold (an overflow, or NaN).

    The message is one line: which stage, what it computed, where the first bad value is."""


def first_bad(a) -> tuple | None:
    """The index of the first non-finite entry of ``a``, or None when every entry is finite."""
    a = np.asarray(a)
    if a.dtype.kind not in "fc" or a.size == 0:
        return None
    if a.dtype.kind == "f" and np.isfinite(np.max(a)) and np.isfinite(np.min(a)):
        return None  # (the extremes propagate NaN and hold any inf: finite without a mask as large as a)
    bad = ~np.isfinite(a)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), a.shape))


def check_finite(a, what: str, rerun=None) -> None:
    """Raise unless every entry of ``a`` is finite (``what``: a string, or a callable making it).

    ``rerun``: a callable that runs the stage again eagerly (``jax.disable_jit``) on the part
    that went wrong; a plugin hook behind the bad value then raises its own one-line
    GiftInputError there. Otherwise (or when the rerun finds every hook finite) this raises
    :class:`NotFinite` naming ``what`` and the index and value of the first bad entry.
    """
    i = first_bad(a)
    if i is None:
        return
    if rerun is not None:
        rerun(i)
    v = float(np.asarray(a)[i])
    what = what() if callable(what) else what
    raise NotFinite(f"{what} is not finite ({v!r} at index {list(i)}): a value beyond what float32, the "
                    f"precision gift computes in, can hold")


def check_all_finite(arrays, whats, rerun=None) -> None:
    """:func:`check_finite` over a sequence of arrays, ``whats`` naming each; ``rerun(k, index)``."""
    for k, (a, what) in enumerate(zip(arrays, whats)):
        check_finite(a, what, None if rerun is None else (lambda i, k=k: rerun(k, i)))
