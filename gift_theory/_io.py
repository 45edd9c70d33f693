"""Files that never exist half-written: one atomic writer for every file gift writes.

Every writer goes through :func:`atomic_path`: the content is written to a temp file in the
destination's folder, which then gets the usual permissions (``mkstemp`` makes 0600) and is
renamed over the destination with ``os.replace`` (atomic on POSIX). A writer that raises, or
a process killed mid-write, leaves the old file untouched and no temp file behind (but for a
SIGKILL, which can leave a ``.tmp-`` file that is never read).
"""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
import zipfile
import zlib
from typing import Callable

from ._errors import require

#: what reading an .npz (a zip archive) raises on a damaged or unreadable file: a broken archive
#: (BadZipFile, struct.error, zlib.error, EOFError), a header zipfile refuses (NotImplementedError:
#: a zip version or compression method it does not know; RuntimeError: an encrypted member),
#: an unreadable file (OSError), a bad array header (ValueError) or a missing member (KeyError)
NPZ_READ_ERRORS = (zipfile.BadZipFile, struct.error, zlib.error, EOFError, RuntimeError, OSError, ValueError,
                   KeyError)


@contextlib.contextmanager
def atomic_path(path, *, make_folder: bool = True):
    """A temp path next to ``path``; on a clean exit it replaces ``path``.

    ``make_folder``: create the destination folder (else a missing folder is a bad input).
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if make_folder:
        os.makedirs(folder, exist_ok=True)
    else:
        require(os.path.isdir(folder), f"{path}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=os.path.splitext(path)[1], dir=folder)
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write(path, write: Callable, *, make_folder: bool = True) -> str:
    """``write(fh)`` into a binary file handle; the file appears at ``path`` only when done."""
    with atomic_path(path, make_folder=make_folder) as tmp:
        with open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
    return os.fspath(path)


def atomic_write_bytes(path, data: bytes, *, make_folder: bool = True) -> str:
    return atomic_write(path, lambda fh: fh.write(data), make_folder=make_folder)


def atomic_write_text(path, text: str, *, make_folder: bool = True) -> str:
    return atomic_write_bytes(path, text.encode(), make_folder=make_folder)


def save_figure(fig, path, **savefig_kw) -> str:
    """``fig.savefig`` atomically (format from the extension), then close the figure."""
    import matplotlib.pyplot as plt

    fmt = os.path.splitext(os.fspath(path))[1][1:] or "png"
    try:
        atomic_write(path, lambda fh: fig.savefig(fh, format=fmt, **{"dpi": 120, **savefig_kw}))
    finally:
        plt.close(fig)
    return os.fspath(path)
