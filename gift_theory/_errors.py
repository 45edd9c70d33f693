"""The one exception type for bad input.

Anything a user can get wrong (a file, an argument, a shape) raises
:class:`GiftInputError` with one line that says what is wrong and where. The
command line turns it into that line on stderr and exit status 2.
"""

from __future__ import annotations


class GiftInputError(ValueError):
    """Bad input: malformed file, bad argument, mismatched shapes.

    The message is one line: what is wrong and where.
    """

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def require(condition: bool, message: str) -> None:
    """Raise :class:`GiftInputError` with ``message`` unless ``condition``."""
    if not condition:
        raise GiftInputError(message)
