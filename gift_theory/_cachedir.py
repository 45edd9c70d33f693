"""gift's cache folder and what happens when it cannot be used.

Everything gift keeps between runs -- trained weights (:mod:`gift_theory.training`), the memo of
in-silico work (:mod:`gift_theory._memo`), compiled programs (:mod:`gift_theory._xla`) -- lives
under :func:`cache_dir`. A cache only saves time: a folder that cannot be written (read-only,
full, not a folder) or an entry that cannot be read (truncated, damaged) never costs a result.
The work is done, the result goes where it was asked (``--out``, stdout), an entry that could
not be read is computed again and rewritten, and stderr gets one warning line per kind of
problem (:func:`warn_once`).
"""

from __future__ import annotations

import os
import sys
import tempfile

_WARNED: set = set()


def cache_dir() -> str:
    """``$GIFT_CACHE_DIR`` or ``~/.cache/gift``."""
    return os.environ.get("GIFT_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "gift")


def warn_once(kind: str, message: str) -> None:
    """One line ``gift: warning: MESSAGE`` on stderr, the first time a problem of ``kind`` is seen."""
    if kind in _WARNED:
        return
    _WARNED.add(kind)
    try:
        sys.stderr.write(f"gift: warning: {message}\n")
        sys.stderr.flush()
    except (OSError, ValueError):  # a closed stderr: nothing to tell
        pass


def writable(folder: str) -> str | None:
    """None when ``folder`` exists or can be made and a file can be written in it; else why not."""
    try:
        os.makedirs(folder, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    return None


def unwritable(folder: str, why, what: str = "") -> None:
    """Warn once that the cache ``folder`` cannot be written (``why``: an OSError or a reason);
    the run goes on without keeping anything there."""
    if isinstance(why, BaseException):
        why = getattr(why, "strerror", None) or str(why) or type(why).__name__
    warn_once("unwritable", f"cannot write the cache {folder} ({why}); nothing is kept there this run"
                            f"{' (' + what + ')' if what else ''}, the results are not affected (set GIFT_CACHE_DIR "
                            f"to a writable folder to keep them)")
