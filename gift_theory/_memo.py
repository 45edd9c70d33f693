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
  (:func:`use_folder`, or ``$GIFT_MEMO_DIR``), in ``<folder>/<tag>-<digest>.npz``, written
  atomically, so that other worker processes and later runs reuse it;
* an entry on disk holds data only, never code: its arrays, and the shape of the result as JSON
  (tuples, lists, dicts with string keys, the weights' ``Layer``, numbers, strings, None),
  read with ``allow_pickle=False``; it carries the digest of its content and its key, checked
  on reading. An entry that fails either (truncated, damaged, planted) is computed again and
  rewritten; a folder that cannot be written costs the reuse, never the result (one warning);
* a hit returns exactly the bits the computation returned (the arrays as saved, put back on
  the device with their dtype).

:func:`counters` says how many results were reused and how many seconds computing the others
took, so a sweep can report what it shared.
"""

from __future__ import annotations

import collections
import functools
import hashlib
import json
import os
import time

import jax
import numpy as np

from ._cachedir import unwritable, warn_once
from ._io import NPZ_READ_ERRORS, atomic_write_bytes

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


def _named_types() -> dict:
    """The named tuples an entry may hold, by name (an entry never names a class to import)."""
    from ._params import Layer

    return {"Layer": Layer}


def _encode(value, arrays: list):
    """``value`` as JSON-able data, its arrays appended to ``arrays`` (referred to by position)."""
    if value is None or isinstance(value, (bool, str)):
        return {"v": value}
    if isinstance(value, int):
        return {"int": value}
    if isinstance(value, float):
        return {"float": repr(value)}
    if isinstance(value, (np.ndarray, np.generic, jax.Array)):
        arrays.append(np.asarray(value))
        return {"array": len(arrays) - 1, "jax": isinstance(value, jax.Array), "scalar": isinstance(value, np.generic)}
    named = {cls: name for name, cls in _named_types().items()}
    if type(value) in named:
        return {"named": named[type(value)], "items": [_encode(v, arrays) for v in value]}
    if isinstance(value, (tuple, list)) and type(value) in (tuple, list):
        return {type(value).__name__: [_encode(v, arrays) for v in value]}
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {"dict": [[k, _encode(v, arrays)] for k, v in value.items()]}
    raise TypeError(f"memo: a result holding {type(value).__name__} cannot be kept as data")


def _decode(node, arrays):
    if "v" in node:
        return node["v"]
    if "int" in node:
        return int(node["int"])
    if "float" in node:
        return float(node["float"])
    if "array" in node:
        a = arrays[int(node["array"])]
        if node.get("scalar"):
            return a[()]
        return jax.numpy.asarray(a) if node.get("jax") else a
    if "named" in node:
        return _named_types()[node["named"]](*(_decode(v, arrays) for v in node["items"]))
    if "tuple" in node:
        return tuple(_decode(v, arrays) for v in node["tuple"])
    if "list" in node:
        return [_decode(v, arrays) for v in node["list"]]
    if "dict" in node:
        return {k: _decode(v, arrays) for k, v in node["dict"]}
    raise ValueError("memo: an entry's skeleton holds an unknown node")


def _content_digest(key: str, skeleton: str, arrays) -> str:
    h = hashlib.sha256(f"{key};{skeleton};".encode())
    for a in arrays:
        _update(h, a)
    return h.hexdigest()


def _to_bytes(key: str, value) -> bytes:
    import io

    arrays: list = []
    skeleton = json.dumps(_encode(value, arrays), separators=(",", ":"))
    buf = io.BytesIO()
    np.savez(buf, __key__=np.array(key), __skeleton__=np.array(skeleton),
             __digest__=np.array(_content_digest(key, skeleton, arrays)), **{f"a{i}": a for i, a in enumerate(arrays)})
    return buf.getvalue()


def _read_entry(path: str, key: str):
    """The value stored at ``path`` for ``key``; raises ValueError (or OSError) when the entry is not
    a well-formed, untampered entry of that key."""
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as f:  # our handle: closed on a bad file
        files = set(f.files)
        if not {"__key__", "__skeleton__", "__digest__"} <= files:
            raise ValueError("not a memo entry")
        skeleton, digest_ = str(f["__skeleton__"]), str(f["__digest__"])
        if str(f["__key__"]) != key:
            raise ValueError("an entry of another key")
        n = len([k for k in files if k.startswith("a") and k[1:].isdigit()])
        arrays = [f[f"a{i}"] for i in range(n)]
    if _content_digest(key, skeleton, arrays) != digest_:
        raise ValueError("its digest does not match its content")
    return _decode(json.loads(skeleton), arrays)


def _key(tag: str, parts) -> str:
    return f"{tag}-{digest(code_digest(), tag, parts)}"


def _path(key: str) -> str | None:
    where = folder()
    return os.path.join(where, key + ".npz") if where else None


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
            value = _read_entry(path, key)
        except NPZ_READ_ERRORS as exc:  # (json.JSONDecodeError is a ValueError)
            warn_once("broken entry", f"memo entry {path} is unreadable ({type(exc).__name__}: {exc}); computed again")
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
        try:
            atomic_write_bytes(path, _to_bytes(key, value))
        except OSError as exc:  # a read-only or full folder: the result is kept in this process only
            unwritable(os.path.dirname(path), exc, "in-silico results")
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
