"""Argument helpers shared by the subcommands (validation turns into one-line errors)."""

from __future__ import annotations

import argparse

from .._arch import Architecture
from .._errors import GiftInputError


def nonneg_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not v >= 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number >= 0")
    return v


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive integer")
    return v


def nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    return v


def arch_arg(text: str) -> Architecture:
    try:
        return Architecture.parse(text)
    except GiftInputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_data_arguments(parser, default: str = "digits") -> None:
    from ..data import DATASETS

    parser.add_argument("--dataset", default=default, choices=DATASETS, help=f"data set (default {default})")
    parser.add_argument("--data-folder", default=None, metavar="DIR",
                        help="folder with the MNIST IDX files (for --dataset mnist)")


def default_arch(dataset: str) -> Architecture:
    return Architecture((784, 500, 100, 100, 10)) if dataset in ("mnist5k", "mnist") else Architecture((64, 32, 32, 10))
