"""Measurement files (CONTRACTS §3): load, validate, save, import and export CSV.

One file is one measurement campaign on one device with one set of programmed weights::

    x (n, d_0)            the inputs sent
    y (n, r, d_L)         r repeated shots of the output per input
    a1..a{L-1} (n, r, d_l) optional taps (the measured hidden-layer outputs, same shots as y)
    W1..WL, b1..bL        the programmed weights
    t (n, r)              optional normalised acquisition times in [0, 1]
    activation ()         string, "tanh" unless told

Every malformed file raises :class:`gift_theory.GiftInputError` with one line naming the
file and what is wrong; nothing is half-written (:mod:`gift_theory._io`). The campaign
itself is :class:`gift_theory.Measurement`, the type chips return.
"""

from __future__ import annotations

import os
import zipfile

import numpy as np

from .._arch import ACTIVATIONS
from .._errors import GiftInputError, require
from .._io import atomic_write
from .._measurement import Measurement
from .._params import Layer


def _float_array(arrays, key, where):
    a = arrays[key]
    require(a.dtype.kind in "fiu", f"{where}: {key} has dtype {a.dtype}, expected float")
    a = np.asarray(a, dtype=np.float64)
    require(bool(np.all(np.isfinite(a))), f"{where}: {key} contains NaN or Inf")
    return a


def validate_arrays(arrays, where: str = "measurement") -> Measurement:
    """Build a :class:`Measurement` from a mapping of arrays, checking every CONTRACTS §3 rule.

    Raises
    ------
    GiftInputError
        One line naming ``where`` and the first problem found.
    """
    keys = set(arrays.keys())
    for k in ("x", "y", "W1", "b1"):
        require(k in keys, f"{where}: missing key {k!r} (a measurement needs x, y, W1..WL, b1..bL)")
    x = _float_array(arrays, "x", where)
    y = _float_array(arrays, "y", where)
    require(x.ndim == 2, f"{where}: x has shape {x.shape}, expected (n, d_0)")
    require(y.ndim == 3, f"{where}: y has shape {y.shape}, expected (n, r, d_L)")
    n, d0 = x.shape
    require(n >= 1 and d0 >= 1, f"{where}: x has shape {x.shape}, needs at least one input of one feature")
    require(y.shape[0] == n, f"{where}: y has {y.shape[0]} inputs, x has {n}")
    r = y.shape[1]
    require(r >= 2, f"{where}: y has {r} shot(s) per input; comparing distributions needs at least 2")
    params = []
    l = 1
    while f"W{l}" in keys:
        require(f"b{l}" in keys, f"{where}: has W{l} but no b{l}")
        W = _float_array(arrays, f"W{l}", where)
        b = _float_array(arrays, f"b{l}", where)
        require(W.ndim == 2, f"{where}: W{l} has shape {W.shape}, expected a matrix (d_{l}, d_{l - 1})")
        d_in = d0 if l == 1 else params[-1].W.shape[0]
        require(W.shape[1] == d_in, f"{where}: W{l} has shape {W.shape} but its input width is {d_in}"
                + (" (the width of x)" if l == 1 else f" (the rows of W{l - 1})"))
        require(b.shape == (W.shape[0],), f"{where}: b{l} has shape {b.shape}, W{l} needs ({W.shape[0]},)")
        params.append(Layer(W, b))
        l += 1
    L = len(params)
    extra_b = sorted(k for k in keys if k.startswith("b") and k[1:].isdigit() and int(k[1:]) > L)
    if extra_b:
        raise GiftInputError(f"{where}: has {extra_b[0]} but no W{extra_b[0][1:]}")
    require(y.shape[2] == params[-1].W.shape[0],
            f"{where}: y has {y.shape[2]} outputs per shot, W{L} has {params[-1].W.shape[0]} rows")
    tap_keys = sorted((k for k in keys if k.startswith("a") and k[1:].isdigit()), key=lambda k: int(k[1:]))
    taps = None
    if tap_keys:
        want = [f"a{l}" for l in range(1, L)]
        require(L >= 2, f"{where}: has taps {tap_keys[0]} but the network has a single layer")
        bad = [k for k in tap_keys if k not in want]
        if bad:
            raise GiftInputError(f"{where}: tap {bad[0]} does not name a hidden layer (the network has a1..a{L - 1})")
        missing = [k for k in want if k not in keys]
        if missing:
            raise GiftInputError(f"{where}: taps are partial: has {tap_keys[0]} but not {missing[0]} "
                                 f"(give all of a1..a{L - 1} or none)")
        taps = []
        for l in range(1, L):
            a = _float_array(arrays, f"a{l}", where)
            want_shape = (n, r, params[l - 1].W.shape[0])
            require(a.shape == want_shape, f"{where}: tap a{l} has shape {a.shape}, expected {want_shape} "
                                           f"(inputs, shots of y, rows of W{l})")
            taps.append(a)
        taps = tuple(taps)
    t = None
    if "t" in keys:
        t = _float_array(arrays, "t", where)
        require(t.shape == (n, r), f"{where}: t has shape {t.shape}, expected (n, r) = {(n, r)}")
        require(bool(np.all((t >= 0) & (t <= 1))), f"{where}: t has values outside [0, 1]")
    activation = "tanh"
    if "activation" in keys:
        act = arrays["activation"]
        try:
            activation = str(np.asarray(act).item()) if np.asarray(act).dtype.kind in "USO" else None
        except ValueError:
            activation = None
        require(activation is not None, f"{where}: activation must be a string, got {np.asarray(act)!r}")
        if isinstance(activation, bytes):
            activation = activation.decode()
        require(activation in ACTIVATIONS, f"{where}: unknown activation {activation!r}; known: {', '.join(ACTIVATIONS)}")
    return Measurement(x=x, y=y, params=tuple(params), taps=taps, t=t, activation=activation)


def load_measurement(path, *, weights=None) -> Measurement:
    """Load and validate a measurement file: ``.npz`` (CONTRACTS §3) or long-format ``.csv``.

    Parameters
    ----------
    path : str or PathLike
    weights : optional ``.npz`` with W1..WL, b1..bL (and ``activation``) for a CSV file,
        whose rows carry no weights.
    """
    path = os.fspath(path)
    require(os.path.exists(path), f"{path}: no such file")
    if path.lower().endswith(".csv"):
        return load_csv(path, weights=weights)
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise GiftInputError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    if weights is not None:
        w = load_weights(weights)
        arrays = {**w, **arrays}
    return validate_arrays(arrays, where=path)


def load_weights(path) -> dict:
    """The arrays W1..WL, b1..bL (and ``activation``) of a weights ``.npz``, checked to exist."""
    path = os.fspath(path)
    require(os.path.exists(path), f"{path}: no such weights file")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files if (k[:1] in "Wb" and k[1:].isdigit()) or k == "activation"}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise GiftInputError(f"{path}: not a readable .npz weights file ({type(exc).__name__})") from None
    require("W1" in arrays, f"{path}: no weights (expected keys W1, b1, ...)")
    return arrays


def load_csv(path, *, weights=None) -> Measurement:
    """Long-format CSV: one row per value, columns ``input, shot, layer, neuron, value``.

    ``layer`` 0 holds the inputs x (one row per input and feature; the shot column is
    ignored there), layers 1..L-1 the taps, layer L the outputs y. An optional column
    ``t`` gives the shot's acquisition time. Weights (W1..WL, b1..bL) come from the
    ``weights`` .npz file; columns may appear in any order, a header row is required.
    """
    path = os.fspath(path)
    require(weights is not None, f"{path}: a CSV measurement needs --weights FILE.npz with W1..WL, b1..bL")
    warrays = load_weights(weights)
    try:
        with open(path, newline="") as fh:
            header = fh.readline().strip().split(",")
            header = [h.strip().lower() for h in header]
            rows = np.loadtxt(fh, delimiter=",", ndmin=2, dtype=np.float64)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise GiftInputError(f"{path}: not a readable numeric CSV ({exc})") from None
    need = ["input", "shot", "layer", "neuron", "value"]
    for c in need:
        require(c in header, f"{path}: missing column {c!r} (need input, shot, layer, neuron, value)")
    require(rows.shape[0] > 0 and rows.shape[1] == len(header), f"{path}: rows do not match the header's {len(header)} columns")
    require(bool(np.all(np.isfinite(rows))), f"{path}: contains NaN or Inf")
    col = {c: rows[:, header.index(c)] for c in header}
    idx = {}
    for c in ("input", "shot", "layer", "neuron"):
        v = col[c]
        require(bool(np.all(v == np.round(v))) and bool(np.all(v >= 0)), f"{path}: column {c} must hold non-negative integers")
        idx[c] = v.astype(np.int64)
    L = sum(1 for k in warrays if k.startswith("W"))
    widths = [int(np.shape(warrays["W1"])[1])] + [int(np.shape(warrays[f"W{l}"])[0]) for l in range(1, L + 1) if f"W{l}" in warrays]
    require(int(idx["layer"].max()) <= L, f"{path}: layer {int(idx['layer'].max())} but the weights have {L} layers")
    n = int(idx["input"].max()) + 1
    out_rows = idx["layer"] == L
    require(bool(out_rows.any()), f"{path}: no rows of the output layer {L}")
    r = int(idx["shot"][out_rows].max()) + 1
    arrays = dict(warrays)
    for l in range(0, L + 1):
        sel = idx["layer"] == l
        if not sel.any():
            require(l not in (0, L), f"{path}: no rows for layer {l}")
            continue
        d = widths[l]
        require(int(idx["neuron"][sel].max()) < d, f"{path}: layer {l} has neuron {int(idx['neuron'][sel].max())}, width is {d}")
        if l == 0:
            a = np.full((n, d), np.nan)
            a[idx["input"][sel], idx["neuron"][sel]] = col["value"][sel]
            require(not np.isnan(a).any(), f"{path}: the inputs (layer 0) miss some (input, neuron) values")
            arrays["x"] = a
        else:
            require(int(idx["shot"][sel].max()) < r, f"{path}: layer {l} has more shots than the output layer")
            a = np.full((n, r, d), np.nan)
            flat = (idx["input"][sel] * r + idx["shot"][sel]) * d + idx["neuron"][sel]
            require(len(np.unique(flat)) == len(flat), f"{path}: layer {l} repeats an (input, shot, neuron) row")
            a.reshape(-1)[flat] = col["value"][sel]
            require(not np.isnan(a).any(), f"{path}: layer {l} misses some (input, shot, neuron) values")
            arrays["y" if l == L else f"a{l}"] = a
    if "t" in col:
        sel = out_rows
        t = np.full((n, r), np.nan)
        t[idx["input"][sel], idx["shot"][sel]] = col["t"][sel]
        require(not np.isnan(t).any(), f"{path}: column t misses some (input, shot) values")
        arrays["t"] = t
    return validate_arrays(arrays, where=path)


def save_csv(path, meas: Measurement) -> None:
    """Write ``meas`` in the long CSV format of :func:`load_csv` (atomically)."""
    rows = []
    n, r = meas.n, meas.r
    ii, jj = np.meshgrid(np.arange(n), np.arange(meas.x.shape[1]), indexing="ij")
    rows.append(np.stack([ii.ravel(), np.zeros(ii.size), np.zeros(ii.size), jj.ravel(), meas.x.ravel()], 1))
    for l, a in zip(meas.layer_ids(), meas.layers()):
        i, s, k = np.meshgrid(np.arange(n), np.arange(r), np.arange(a.shape[2]), indexing="ij")
        rows.append(np.stack([i.ravel(), s.ravel(), np.full(i.size, l), k.ravel(), a.ravel()], 1))
    data = np.concatenate(rows)
    header = "input,shot,layer,neuron,value"
    if meas.t is not None:
        tcol = np.zeros(len(data))
        sel = data[:, 2] > 0
        tcol[sel] = meas.t[data[sel, 0].astype(int), data[sel, 1].astype(int)]
        data = np.concatenate([data, tcol[:, None]], 1)
        header += ",t"
    atomic_write(path, lambda fh: np.savetxt(fh, data, delimiter=",", header=header, comments="",
                                              fmt=["%d", "%d", "%d", "%d", "%.9g"] + (["%.9g"] if meas.t is not None else [])),
                 make_folder=False)


def save_measurement(path, meas: Measurement) -> None:
    """Write ``meas`` as a CONTRACTS §3 ``.npz`` (atomically)."""
    arrays = meas.arrays()
    atomic_write(path, lambda fh: np.savez(fh, **arrays), make_folder=False)
