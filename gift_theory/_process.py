"""Process-level settings of the ``gift`` command (a script that imports gift_theory gets none)."""

from __future__ import annotations


def fewer_malloc_arenas(arenas: int = 2) -> None:
    """Ask glibc for at most ``arenas`` malloc arenas (a no-op elsewhere). Every thread that
    allocates gets an arena of its own by default (8 per core), and the freed memory of numpy's
    many mid-sized temporaries stays in them: measured on the 50 MB file, ``gift compare`` peaked
    at 1.05 GB with the default and 0.85 GB with two arenas, the same numbers."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    if not name:
        return
    try:
        libc = ctypes.CDLL(name)
        libc.mallopt(ctypes.c_int(-8), ctypes.c_int(int(arenas)))  # M_ARENA_MAX
    except (OSError, AttributeError):  # not glibc
        pass
