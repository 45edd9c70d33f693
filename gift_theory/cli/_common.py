"""Helpers shared by the subcommands: argument validation with one wording per rule, "did you
mean" for unknown names, and i/N progress with the time left on stderr."""

from __future__ import annotations

import argparse
import difflib
import math
import re
import sys
import time

from .._arch import Architecture
from .._errors import GiftInputError

#: the reference page every ``--help`` points to (file formats, JSON outputs, effect table)
REFERENCE = "docs/reference.md in the gift repository"


# ------------------------------------------------------------------------------------------
# numbers: one wording per rule, whichever command reports it
# ------------------------------------------------------------------------------------------
def _number(text: str, kind=float) -> float:
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
    if kind is float and not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0."""
    v = _number(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number > 0")
    return v


def nonneg_float(text: str) -> float:
    """A finite number >= 0."""
    v = _number(text)
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number >= 0")
    return v


def positive_int(text: str) -> int:
    """An integer >= 1."""
    v = _number(text, int)
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be an integer >= 1")
    return v


def nonneg_int(text: str) -> int:
    """An integer >= 0."""
    v = _number(text, int)
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be an integer >= 0")
    return v


def arch_arg(text: str) -> Architecture:
    try:
        return Architecture.parse(text)
    except GiftInputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_data_arguments(parser, default: str = "digits") -> None:
    """``--dataset`` and ``--data-folder`` (the MNIST IDX folder), as every command that trains takes them."""
    from ..data import DATASETS

    parser.add_argument("--dataset", default=default, choices=DATASETS,
                        help=f"data set: {', '.join(DATASETS)} (default {default}; mnist needs --data-folder)")
    parser.add_argument("--data-folder", default=None, metavar="DIR",
                        help="folder with the four MNIST IDX files (train/t10k images/labels, optionally .gz), "
                             "for --dataset mnist")


def check_data_folder(args) -> None:
    """``--dataset mnist`` needs ``--data-folder``; other data sets take none."""
    if args.dataset == "mnist" and not args.data_folder:
        raise GiftInputError("--dataset mnist: name the folder holding the MNIST IDX files with --data-folder DIR")
    if args.data_folder and args.dataset != "mnist":
        raise GiftInputError(f"--data-folder: only --dataset mnist reads a folder (got --dataset {args.dataset})")


def default_arch(dataset: str) -> Architecture:
    return Architecture((784, 500, 100, 100, 10)) if dataset in ("mnist5k", "mnist") else Architecture((64, 32, 32, 10))


# ------------------------------------------------------------------------------------------
# did you mean
# ------------------------------------------------------------------------------------------
_UNKNOWN = re.compile(r"unknown (?:[a-z ]+?) '(?P<name>[^']+)'.*?(?:known|commands|parts|choose from): (?P<known>.+)$")
_CHOICE = re.compile(r"invalid choice: '(?P<name>[^']+)' \(choose from (?P<known>[^)]*)\)")


def suggest(name: str, known) -> str | None:
    """The closest of ``known`` to ``name`` (difflib), or None."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return close[0] if close else None


def did_you_mean(message: str) -> str:
    """``message`` with " (did you mean 'x'?)" added when it names an unknown name and lists
    the known ones ("unknown effect 'shto'; known: awgn, shot, ..." or argparse's invalid choice)."""
    m = _UNKNOWN.search(message) or _CHOICE.search(message)
    if not m or "did you mean" in message:
        return message
    known = [k.strip().strip("'\"") for k in m.group("known").split(",")]
    best = suggest(m.group("name"), known)
    return f"{message} (did you mean {best!r}?)" if best else message


# ------------------------------------------------------------------------------------------
# progress
# ------------------------------------------------------------------------------------------
class Progress:
    """``progress(i, n, label)`` callbacks that print ``prog: [i+1/n] label (t s, ~left s left)``
    on stderr before item i starts (``after=True``: as item i is done); silent when ``quiet``.
    The time left is the mean time of the items timed so far (from the first call on) times the
    items still to run (shown from the second item on, not after the last; ``eta=False`` for
    items of very different lengths, where that mean would mislead)."""

    def __init__(self, prog: str, quiet: bool = False, stream=None, eta: bool = True, after: bool = False):
        self.prog, self.quiet, self.eta, self.after = prog, quiet, eta, after
        self.stream = stream
        self.t0 = None
        self.first = 0

    def __call__(self, i: int, n: int, label: str) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        if self.t0 is None or i == 0:
            self.t0, self.first = now, i
        done = i - self.first
        elapsed = now - self.t0
        # items to run: from item i on (before it starts), after item i (when it is done) -- the
        # diagnosis reports a candidate done, and counting it still to run put ~3 s left on the last
        todo = n - i - (1 if self.after else 0)
        left = f", ~{elapsed / done * todo:.0f} s left" if done > 0 and todo > 0 and self.eta else ""
        out = self.stream or sys.stderr
        out.write(f"{self.prog}: [{i + 1}/{n}] {label} ({elapsed:.0f} s{left})\n")
        out.flush()
