"""Deterministic work done once: a content-addressed memo for in-silico results.

Many fine-tuning runs share their in-silico part. Every run on the same trained weights w0,
training data, s0 and seed has the same GIFT direction, the same curvature u^T H u, the same
paired-Eval standard error and the same slope at s0, whatever the chip's noise: these are free
computations at s0 whose draws are named by the seed. A sweep over the chip's noise level and
law repeats them at every point. :func:`memoized` computes such a result once and reuses it:

* the key is a digest of everything the result depends on, the arrays' bytes, shapes and dtypes,
  the scalars, the PRNG key's data, the physics' leaves, plus the source of ``gift_theory`` and
  the jax version (a change of the code is a different key, never a stale hit);
* a result is kept in this process (the last :data:`KEEP` of them) and, when a folder is set
  (:func:`use_folder`, or ``$GIFT_MEMO_DIR``), in ``<folder>/<tag>-<digest>.pkl``, written
  atomically, so that other worker processes and later runs reuse it;
* a hit returns exactly the bits the computation returned (the arrays as saved, put back on
  the device with their dtype).

:func:`counters` says how many results were reused and how many seconds computing the others
took, so a sweep can report what it shared.
"""

from __future__ import annotations

import collections
import functools
import hashlib
import os
import pickle
import time

import jax
import numpy as np

from ._io import atomic_write_bytes

#: results kept in process
KEEP = 32
_mem: "collections.OrderedDict[str, object]" = collections.OrderedDict()
_folder: list = [None]
_count: dict = collections.defaultdict(lambda: {"hits": 0, "misses": 0, "seconds_computed": 0.0})


def use_folder(folder: str | None) -> None:
    """Also keep results in ``folder`` (None: in process only, unless ``$GIFT_MEMO_DIR``)."""
    _folder[0] = None if folder is None else os.fspath(folder)


def folder() -> str | None:
    return _folder[0] or os.environ.get("GIFT_MEMO_DIR") or None


def counters() -> dict:
    """Per tag: hits, misses and seconds spent computing the misses, since the process started."""
    return {tag: dict(c) for tag, c in _count.items()}


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """A digest of gift_theory's source and the jax version (part of every key)."""
    h = hashlib.sha256(jax.__version__.encode())
    root = os.path.dirname(os.path.abspath(__file__))
    for base, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for f in sorted(files):
            if f.endswith(".py"):
                with open(os.path.join(base, f), "rb") as fh:
                    h.update(f.encode() + fh.read())
    return h.hexdigest()


def _update(h, obj) -> None:
    if obj is None or isinstance(obj, (bool, int, float, str)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
        return
    if isinstance(obj, (np.ndarray, np.generic, jax.Array)):
        if isinstance(obj, jax.Array) and jax.dtypes.issubdtype(obj.dtype, jax.dtypes.prng_key):
            obj = jax.random.key_data(obj)
        a = np.ascontiguousarray(np.asarray(obj))
        h.update(f"array:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
        return
    if isinstance(obj, dict):
        h.update(b"dict{")
        for k in sorted(obj, key=str):
            _update(h, str(k))
            _update(h, obj[k])
        h.update(b"}")
        return
    leaves, tree = jax.tree_util.tree_flatten(obj)
    if tree.num_leaves == 1 and leaves and leaves[0] is obj:  # not a container: its repr names it
        h.update(f"{type(obj).__qualname__}:{obj!r};".encode())
        return
    h.update(f"tree:{tree};".encode())
    for leaf in leaves:
        _update(h, leaf)


def digest(*parts) -> str:
    """A hex digest of ``parts`` (arrays by content, containers and pytrees leaf by leaf)."""
    h = hashlib.sha256()
    for p in parts:
        _update(h, p)
    return h.hexdigest()[:32]


def _to_host(value):
    return jax.tree_util.tree_map(lambda a: np.asarray(a) if isinstance(a, jax.Array) else a, value)


def _to_device(value):
    return jax.tree_util.tree_map(lambda a: jax.numpy.asarray(a) if isinstance(a, np.ndarray) else a, value)


def _key(tag: str, parts) -> str:
    return f"{tag}-{digest(code_digest(), tag, parts)}"


def _path(key: str) -> str | None:
    where = folder()
    return os.path.join(where, key + ".pkl") if where else None


def lookup(tag: str, parts):
    """The stored result for ``tag`` and ``parts``, or None (see :func:`memoized`)."""
    key = _key(tag, parts)
    if key in _mem:
        _mem.move_to_end(key)
        _count[tag]["hits"] += 1
        return _fresh(_mem[key])
    path = _path(key)
    if path and os.path.isfile(path):
        try:
            with open(path, "rb") as fh:
                value = _to_device(pickle.load(fh))
        except (OSError, EOFError, pickle.UnpicklingError):
            return None  # an unreadable entry is recomputed and rewritten
        _count[tag]["hits"] += 1
        _keep(key, value)
        return _fresh(value)
    return None


def store(tag: str, parts, value, seconds: float = 0.0) -> None:
    """Keep ``value`` as the result for ``tag`` and ``parts`` (``seconds``: what computing it took)."""
    key = _key(tag, parts)
    _count[tag]["seconds_computed"] += float(seconds)
    _count[tag]["misses"] += 1
    path = _path(key)
    if path:
        atomic_write_bytes(path, pickle.dumps(_to_host(value), protocol=pickle.HIGHEST_PROTOCOL))
    _keep(key, value)


def memoized(tag: str, parts, compute):
    """``compute()``, or the result of an earlier call with the same ``tag`` and ``parts``.

    ``parts`` must name everything the result depends on (arrays, scalars, keys, physics);
    ``compute`` must be deterministic in them. The result is a pytree of arrays and Python
    scalars (and dicts/tuples of them).
    """
    value = lookup(tag, parts)
    if value is not None:
        return value
    t0 = time.perf_counter()
    value = jax.block_until_ready(compute())
    store(tag, parts, value, time.perf_counter() - t0)
    return _fresh(value)


def _fresh(value):
    # new containers around the same leaves: a caller that edits a returned dict edits its own
    return jax.tree_util.tree_map(lambda a: a, value)


def _keep(key: str, value) -> None:
    _mem[key] = value
    while len(_mem) > KEEP:
        _mem.popitem(last=False)


def clear() -> None:
    """Forget the in-process results (the folder is left alone)."""
    _mem.clear()
