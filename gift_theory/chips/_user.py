"""A user's own chip driver: ``FILE.py:NAME`` loaded, checked against the Chip protocol, and
scored on fresh shots that its budget does not pay for.

``load_chip("driver.py:make_chip")`` imports the file under a module name of its own, calls
``make_chip()`` and wraps the object it returns in :class:`CheckedChip`, which checks every
measurement the driver hands back (docs/reference.md §7, docs/hardware.md). Whatever is wrong
-- no file, an import error, no ``NAME``, an object without ``widths``, ``ledger`` or
``measure``, a measurement of the wrong shape -- is a bad input: one line naming the file.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import sys

import numpy as np

from .._errors import GiftInputError
from .._measurement import Measurement
from ._base import BudgetExceeded


def _import(path: str, spec: str):
    real = os.path.realpath(path)
    if not os.path.isfile(real):
        raise GiftInputError(f"--chip {spec}: no such file {path}")
    name = "gift_chip_" + hashlib.sha1(real.encode()).hexdigest()[:12]
    loader = importlib.util.spec_from_file_location(name, real)
    if loader is None:
        raise GiftInputError(f"--chip {spec}: {path} is not a Python file")
    module = importlib.util.module_from_spec(loader)
    sys.modules[name] = module
    try:
        loader.loader.exec_module(module)
    except Exception as exc:  # the user's file: anything it raises is a bad input
        sys.modules.pop(name, None)
        raise GiftInputError(f"--chip {spec}: importing {path} raised {type(exc).__name__}: {exc}") from None
    return module


def load_chip(spec: str, widths=None) -> "CheckedChip":
    """The chip ``NAME()`` returns, from ``spec`` = ``FILE.py:NAME``, checked against the protocol.

    Parameters
    ----------
    spec : ``FILE.py:NAME`` (NAME: a function or class the file defines, called with no argument)
    widths : the architecture the chip must implement (checked when given)

    Raises
    ------
    GiftInputError
        One line naming the file and what is wrong.
    """
    path, sep, name = str(spec).rpartition(":")
    if not sep or not path or not name.isidentifier():
        raise GiftInputError(f"--chip {spec}: expected FILE.py:NAME (NAME a function of the file returning the chip)")
    module = _import(path, spec)
    factory = getattr(module, name, None)
    if not callable(factory):
        raise GiftInputError(f"--chip {spec}: {path} defines no callable {name!r}")
    try:
        chip = factory()
    except Exception as exc:
        raise GiftInputError(f"--chip {spec}: {name}() raised {type(exc).__name__}: {exc}") from None
    return CheckedChip(chip, spec, widths)


class CheckedChip:
    """A user's chip behind the protocol, every measurement it returns checked.

    ``widths``, ``ledger`` are the chip's own; :meth:`measure` forwards to it and checks the
    :class:`~gift_theory.Measurement` it returns (type, shapes of ``y`` and the taps, finite
    values; ``(W, b)`` pairs given as ``params`` are accepted as the programmed weights). A
    driver that raises (other than :class:`BudgetExceeded`) is a bad input naming the file.
    """

    def __init__(self, chip, spec: str, widths=None):
        self.inner, self.spec = chip, str(spec)
        for attr in ("widths", "ledger", "measure"):
            if not hasattr(chip, attr):
                raise GiftInputError(f"--chip {spec}: the object has no {attr!r} (the Chip protocol: widths, ledger, "
                                     "measure(params, x, shots, *, taps=False, key=None); docs/hardware.md)")
        try:
            self.widths = tuple(int(w) for w in chip.widths)
        except (TypeError, ValueError):
            raise GiftInputError(f"--chip {spec}: widths {chip.widths!r} is not a tuple of integers") from None
        if widths is not None and self.widths != tuple(widths):
            raise GiftInputError(f"--chip {spec}: the chip implements {'-'.join(map(str, self.widths))}, the network "
                                 f"is {'-'.join(map(str, widths))}")
        for attr in ("charge", "remaining", "evaluations", "set_budget_evaluations", "shots"):
            if not hasattr(chip.ledger, attr):
                raise GiftInputError(f"--chip {spec}: its ledger has no {attr!r} (use gift_theory.chips.Ledger)")
        if not callable(chip.measure):
            raise GiftInputError(f"--chip {spec}: measure is not callable")
        self.physics = None  # a user's chip hides its physics

    @property
    def ledger(self):
        return self.inner.ledger

    def measure(self, params, x, shots: int, *, taps: bool = False, key=None) -> Measurement:
        try:
            m = self.inner.measure(params, x, shots, taps=taps, key=key)
        except BudgetExceeded:
            raise
        except GiftInputError as exc:
            raise GiftInputError(f"--chip {self.spec}: {exc}") from None
        except Exception as exc:
            raise GiftInputError(f"--chip {self.spec}: measure() raised {type(exc).__name__}: {exc}") from None
        return self._checked(m, params, np.asarray(x), int(shots), bool(taps))

    def _checked(self, m, params, x, shots, taps) -> Measurement:
        spec, L = self.spec, len(self.widths) - 1
        if not isinstance(m, Measurement):
            raise GiftInputError(f"--chip {spec}: measure() returned {type(m).__name__}, not a gift_theory.Measurement")
        n = x.shape[0]
        y = np.asarray(m.y)
        if y.shape != (n, shots, self.widths[-1]):
            raise GiftInputError(f"--chip {spec}: measure() returned y of shape {y.shape}, expected "
                                 f"({n}, {shots}, {self.widths[-1]}) (inputs, shots, outputs)")
        if not np.all(np.isfinite(y)):
            raise GiftInputError(f"--chip {spec}: measure() returned non-finite outputs")
        taps_ = m.taps
        if taps_ is not None:
            if len(taps_) == 0 or not taps:
                taps_ = None
            elif len(taps_) != L - 1 or any(np.asarray(a).shape != (n, shots, self.widths[l + 1])
                                            for l, a in enumerate(taps_)):
                raise GiftInputError(f"--chip {spec}: measure() returned {len(taps_)} taps of shapes "
                                     f"{[np.asarray(a).shape for a in taps_]}, expected the hidden layers 1..{L - 1} "
                                     f"as (inputs, shots, width)")
            elif not all(np.all(np.isfinite(a)) for a in taps_):
                raise GiftInputError(f"--chip {spec}: measure() returned non-finite taps")
        prog = _programmed(m.params, params, L, spec)
        from .._params import Layer
        return Measurement(np.asarray(m.x, np.float64), y.astype(np.float64),
                           tuple(Layer(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in prog),
                           None if taps_ is None else tuple(np.asarray(a, np.float64) for a in taps_),
                           None if m.t is None else np.asarray(m.t, np.float64), m.activation)

    def __repr__(self):
        return f"CheckedChip({self.spec})"


def _programmed(got, sent, L: int, spec: str):
    """The programmed weights of a measurement: what the driver reports, else what was sent."""
    try:
        pairs = [(np.asarray(W), np.asarray(b)) for W, b in got]
        if len(pairs) == L and all(W.ndim == 2 and b.ndim == 1 for W, b in pairs):
            return pairs
    except (TypeError, ValueError):
        pass
    if got is not None and not (isinstance(got, tuple) and len(got) == 0):
        raise GiftInputError(f"--chip {spec}: measure() returned params that are not the {L} programmed (W, b) "
                             "pairs: Measurement(x, y, params, taps=None, t=None) (docs/hardware.md)")
    return [(np.asarray(W), np.asarray(b)) for W, b in sent]


@contextlib.contextmanager
def uncharged(ledger):
    """Shots measured inside are not charged to ``ledger`` (nor held against its budget): a
    score of the chip that the method did not pay for. They are counted in ``ledger.free_shots``."""
    shots, calls, budget = ledger.shots, getattr(ledger, "calls", 0), ledger.budget_shots
    ledger.budget_shots = None
    try:
        yield
    finally:
        ledger.free_shots = getattr(ledger, "free_shots", 0) + ledger.shots - shots
        ledger.shots, ledger.budget_shots = shots, budget
        if hasattr(ledger, "calls"):
            ledger.calls = calls


def chip_scores(chip, weight_sets, x, y, labels, *, shots: int = 32):
    """Per-input losses and correctness (P, n) of P weight sets measured on ``chip`` (fresh shots,
    ``shots`` per input, not charged): the mean over shots of (y - output)^2 summed over outputs,
    and of argmax(output) == label."""
    losses, correct = [], []
    y = np.asarray(y, np.float64)
    labels = np.asarray(labels)
    with uncharged(chip.ledger):
        for p in weight_sets:
            out = np.asarray(chip.measure(p, x, shots).y, np.float64)
            losses.append(np.sum((out - y[:, None, :]) ** 2, axis=-1).mean(axis=1))
            correct.append((np.argmax(out, axis=-1) == labels[:, None]).mean(axis=1))
    return np.stack(losses), np.stack(correct)
