"""Measurement files (reference §3): load, validate, save; .npz, long and wide CSV, netCDF / HDF5.

One file is one measurement campaign on one device with one set of programmed weights::

    x (n, d_0)            the inputs sent
    y (n, r, d_L)         r repeated shots of the output per input
    a1..a{L-1} (n, r, d_l) optional taps (the measured hidden-layer outputs, same shots as y)
    W1..WL, b1..bL        the programmed weights
    t (n, r)              optional normalised acquisition times in [0, 1]
    activation ()         string, "tanh" unless told

The same campaign in the formats labs keep, each read by :func:`load_measurement` (the format
is told by the file's first bytes, else by its extension and a CSV's header):

- ``.npz``: the keys above;
- long CSV: one row per value, ``input, shot, layer, neuron, value`` (:func:`load_csv`);
- wide CSV: one row per (input, shot), ``input, shot, x1..x{d_0}, y1..y{d_L}``, optional
  ``t`` and taps ``a{l}_{j}`` (:func:`load_wide_csv`);
- netCDF / HDF5 (xarray): the variables above with dimensions ``input`` and ``shot``
  (:meth:`Measurement.from_xarray`).

A CSV, and a netCDF file without ``W1``, takes its weights from a ``.npz`` (``weights=``).
Every malformed file raises :class:`gift_theory.GiftInputError` with one line naming the
file and what is wrong; nothing is half-written (:mod:`gift_theory._io`). The campaign
itself is :class:`gift_theory.Measurement`, the type chips return.
"""

from __future__ import annotations

import os
import re
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
    """Build a :class:`Measurement` from a mapping of arrays, checking every reference §3 rule.

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


#: extensions of netCDF / HDF5 files (read and written through xarray's h5netcdf engine)
NETCDF_EXTENSIONS = (".nc", ".nc4", ".cdf", ".h5", ".hdf5", ".he5")
_MAGIC = {b"PK\x03\x04": "npz", b"\x89HDF\r\n\x1a\n": "netcdf", b"CDF\x01": "netcdf3", b"CDF\x02": "netcdf3",
          b"CDF\x05": "netcdf3"}


def detect_format(path) -> str:
    """``"npz"``, ``"netcdf"`` (HDF5-based), ``"netcdf3"``, ``"csv-long"`` or ``"csv-wide"``.

    The first bytes decide for the binary formats (a netCDF file named ``.npz`` is read as
    netCDF); otherwise the extension, and for a CSV its header (``layer, neuron, value``:
    long; ``x1 .. y1 ..``: wide).
    """
    path = os.fspath(path)
    require(os.path.exists(path), f"{path}: no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise GiftInputError(f"{path}: cannot be read ({exc.strerror})") from None
    for magic, fmt in _MAGIC.items():
        if head.startswith(magic):
            return fmt
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npz":
        return "npz"
    if ext in NETCDF_EXTENSIONS:
        raise GiftInputError(f"{path}: not a netCDF / HDF5 file (its first bytes are {head[:4]!r})")
    try:
        with open(path, encoding="utf-8-sig") as fh:
            header = [h.strip().lower() for h in fh.readline().split(",")]
    except UnicodeDecodeError:
        raise GiftInputError(f"{path}: not a measurement file (expected .npz, netCDF / HDF5 or a CSV with a "
                             f"header row)") from None
    if {"layer", "neuron", "value"} <= set(header):
        return "csv-long"
    if "x1" in header or "y1" in header:
        return "csv-wide"
    raise GiftInputError(f"{path}: not a measurement file: a CSV needs the header input,shot,layer,neuron,value "
                         f"(long) or input,shot,x1..,y1.. (wide); this one starts {','.join(header[:6])}")


def load_measurement(path, *, weights=None) -> Measurement:
    """Load and validate a measurement file in any format of the module docstring.

    Parameters
    ----------
    path : str or PathLike
    weights : optional ``.npz`` with W1..WL, b1..bL (and ``activation``) for a file that
        holds no weights (CSV, netCDF without ``W1``).
    """
    path = os.fspath(path)
    fmt = detect_format(path)
    if fmt == "csv-long":
        return load_csv(path, weights=weights)
    if fmt == "csv-wide":
        return load_wide_csv(path, weights=weights)
    if fmt in ("netcdf", "netcdf3"):
        return load_netcdf(path, weights=weights)
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise GiftInputError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    if weights is not None:
        w = load_weight_arrays(weights)
        arrays = {**w, **arrays}
    return validate_arrays(arrays, where=path)


def weights_arrays(weights) -> dict:
    """W1..WL, b1..bL (and ``activation``) from a ``.npz`` path or a mapping of arrays."""
    if isinstance(weights, (str, os.PathLike)):
        return load_weight_arrays(weights)
    return {k: np.asarray(v) for k, v in dict(weights).items() if (k[:1] in "Wb" and k[1:].isdigit()) or k == "activation"}


def _needs_weights(path, arrays, weights):
    if "W1" in arrays:
        return arrays
    require(weights is not None, f"{path}: holds no weights (W1, b1, ...): give --weights FILE.npz")
    return {**weights_arrays(weights), **arrays}


def dataset_arrays(ds, where: str = "dataset") -> dict:
    """The reference §3 arrays of an ``xarray.Dataset``: x as (input, ·), y, taps as (input, shot, ·),
    t as (input, shot) -- dimensions named ``input`` and ``shot`` moved into place -- the weights
    as stored, and the attribute (or variable) ``activation``."""
    out = {}
    want = {"x": ("input",), "y": ("input", "shot"), "t": ("input", "shot")}
    for name in ds.data_vars:
        name = str(name)
        if not (name in ("x", "y", "t", "activation") or re.fullmatch(r"[Wba]\d+", name)):
            continue  # anything else is kept in the file and ignored
        v = ds[name]
        lead = want.get(name, ("input", "shot") if name[0] == "a" else ())
        if lead and all(d in v.dims for d in lead):
            v = v.transpose(*lead, ...)
        elif lead and any(d in v.dims for d in lead):
            missing = [d for d in lead if d not in v.dims]
            raise GiftInputError(f"{where}: variable {name} has dimensions {tuple(map(str, v.dims))}, "
                                 f"no {missing[0]!r} (expected {name} ({', '.join(lead)}, ...))")
        out[name] = np.asarray(v.values)
    if "activation" not in out and "activation" in ds.attrs:
        out["activation"] = np.asarray(ds.attrs["activation"])
    return out


def load_netcdf(path, *, weights=None) -> Measurement:
    """A netCDF (3 or 4) or plain HDF5 file read through xarray; see :meth:`Measurement.from_xarray`."""
    import xarray as xr

    path = os.fspath(path)
    engine = "scipy" if detect_format(path) == "netcdf3" else "h5netcdf"
    kw = {"phony_dims": "sort"} if engine == "h5netcdf" else {}  # plain HDF5 has no dimension names
    try:
        with xr.open_dataset(path, engine=engine, mask_and_scale=False, decode_times=False, **kw) as ds:
            arrays = dataset_arrays(ds.load(), where=path)
    except GiftInputError:
        raise
    except Exception as exc:  # h5py / scipy raise many kinds on a damaged file
        raise GiftInputError(f"{path}: not a readable netCDF / HDF5 file ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    return validate_arrays(_needs_weights(path, arrays, weights), where=path)


def save_netcdf(path, meas: Measurement) -> None:
    """Write ``meas`` as netCDF-4 (HDF5) with the names of :meth:`Measurement.to_xarray` (atomically)."""
    from .._io import atomic_path

    ds = meas.to_xarray()
    with atomic_path(path, make_folder=False) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf")


_WIDE_COLUMN = re.compile(r"^(x|y)(\d+)$|^a(\d+)_(\d+)$")


def _float_or_nan(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _line_of(rows, k) -> int:
    return int(rows[k]) + 2  # the header is line 1


def load_wide_csv(path, *, weights=None) -> Measurement:
    """Wide CSV: one row per (input, shot), columns ``input, shot, x1..x{d_0}, y1..y{d_L}``, an
    optional ``t`` and optional taps ``a{l}_{j}`` (layer l, neuron j, 1-based); any order,
    other columns ignored.

    ``input`` and ``shot`` are integers; inputs are numbered consecutively, every input has
    the same shots, x is the same on every shot of an input. Rows are sorted by (input, shot).
    A bad row is named by its line and its input. Weights come from ``weights`` (a ``.npz``).
    """
    import pandas as pd

    path = os.fspath(path)
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, encoding="utf-8-sig")
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise GiftInputError(f"{path}: not a readable CSV ({type(exc).__name__}: {str(exc).splitlines()[0]})") from None
    cols = [str(c).strip().lower() for c in df.columns]
    dup = sorted({c for c in cols if cols.count(c) > 1})
    require(not dup, f"{path}: column {dup[0] if dup else ''!r} appears twice")
    df.columns = cols
    require(len(df) > 0, f"{path}: no data rows")
    for c in ("input", "shot"):
        require(c in cols, f"{path}: missing column {c!r} (a wide CSV needs input, shot, x1.., y1..)")
    groups = {"x": {}, "y": {}}
    taps = {}
    for c in cols:
        m = _WIDE_COLUMN.match(c)
        if m and m.group(1):
            groups[m.group(1)][int(m.group(2))] = c
        elif m:
            taps.setdefault(int(m.group(3)), {})[int(m.group(4))] = c

    def numbers(c, integer=False):
        raw = df[c].str.strip()
        try:  # numpy parses decimal strings exactly (the shortest repr reads back to the same float)
            v = raw.to_numpy().astype(np.float64)
        except ValueError:
            v = np.array([_float_or_nan(u) for u in raw.tolist()])
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            k = int(bad[0])
            what = "is empty" if raw.iloc[k] == "" else f"is not a finite number ({raw.iloc[k]!r})"
            inp = df["input"].iloc[k].strip() if c != "input" else "?"
            raise GiftInputError(f"{path}: line {k + 2} (input {inp}): column {c} {what}")
        if integer:
            bad = np.flatnonzero(v != np.round(v))
            require(not bad.size, f"{path}: line {int(bad[0]) + 2 if bad.size else 0}: column {c} must hold integers")
        return v

    def block(name, cmap, label):
        require(cmap, f"{path}: no columns {label}1.. (a wide CSV needs x1..x{{d_0}} and y1..y{{d_L}})")
        width = max(cmap)
        missing = [j for j in range(1, width + 1) if j not in cmap]
        require(not missing, f"{path}: has column {label}{width} but not {label}{missing[0] if missing else ''} "
                             f"(columns {label}1..{label}{width} are needed)")
        return np.stack([numbers(cmap[j]) for j in range(1, width + 1)], axis=1)

    inp = numbers("input", integer=True).astype(np.int64)
    shot = numbers("shot", integer=True).astype(np.int64)
    order = np.lexsort((shot, inp))
    inp, shot = inp[order], shot[order]
    ids = np.unique(inp)
    gap = np.flatnonzero(np.diff(ids) > 1)
    if gap.size:
        raise GiftInputError(f"{path}: input {int(ids[gap[0]]) + 1} has no rows (inputs are numbered "
                             f"consecutively from {int(ids[0])} to {int(ids[-1])})")
    same = np.flatnonzero((np.diff(inp) == 0) & (np.diff(shot) == 0))
    if same.size:
        k = int(same[0])
        raise GiftInputError(f"{path}: input {int(inp[k])} shot {int(shot[k])} appears twice "
                             f"(lines {_line_of(order, k)} and {_line_of(order, k + 1)})")
    shots = np.unique(shot)
    n, r = len(ids), len(shots)
    if len(inp) != n * r:
        counts = np.bincount(inp - ids[0], minlength=n)
        i = int(np.argmin(counts))
        have = set(shot[inp == ids[i]].tolist())
        miss = [int(s) for s in shots if int(s) not in have]
        raise GiftInputError(f"{path}: input {int(ids[i])} misses shot {miss[0]} ({counts[i]} of the {r} shots "
                             f"{int(shots[0])}..{int(shots[-1])} the file holds; every input needs every shot)")
    # rows sorted by (input, shot), every input holding every shot: a plain reshape
    x_rows = block("x", groups["x"], "x")[order].reshape(n, r, -1)
    differs = np.any(x_rows != x_rows[:, :1], axis=(1, 2))
    if differs.any():
        i = int(np.flatnonzero(differs)[0])
        s_, j = np.argwhere(x_rows[i] != x_rows[i, :1])[0]
        raise GiftInputError(f"{path}: input {int(ids[i])}: x{j + 1} differs between its shots "
                             f"({x_rows[i, 0, j]!r} on line {_line_of(order, i * r)}, {x_rows[i, s_, j]!r} on line "
                             f"{_line_of(order, i * r + s_)})")
    arrays = {"x": x_rows[:, 0], "y": block("y", groups["y"], "y")[order].reshape(n, r, -1)}
    for l, cmap in taps.items():
        arrays[f"a{l}"] = block(f"a{l}", cmap, f"a{l}_")[order].reshape(n, r, -1)
    if "t" in cols:
        arrays["t"] = numbers("t")[order].reshape(n, r)
    return validate_arrays(_needs_weights(path, arrays, weights), where=path)


def save_wide_csv(path, meas: Measurement) -> None:
    """Write ``meas`` as a wide CSV of :func:`load_wide_csv` (atomically; every float as its
    shortest exact decimal, so reading it back gives the same numbers). The weights are not
    in it: save them with :func:`save_weights`."""
    n, r = meas.n, meas.r
    header = ["input", "shot"] + (["t"] if meas.t is not None else [])
    blocks = [np.broadcast_to(meas.x[:, None, :], (n, r, meas.x.shape[1]))]
    header += [f"x{j}" for j in range(1, meas.x.shape[1] + 1)]
    blocks.append(meas.y)
    header += [f"y{j}" for j in range(1, meas.y.shape[2] + 1)]
    for l, a in enumerate(meas.taps or (), start=1):
        blocks.append(a)
        header += [f"a{l}_{j}" for j in range(1, a.shape[2] + 1)]
    if meas.t is not None:
        blocks.insert(0, meas.t[:, :, None])
    values = np.concatenate([np.asarray(b, np.float64) for b in blocks], axis=2).reshape(n * r, -1).tolist()
    lines = [",".join(header)]
    lines += [f"{i // r},{i % r}," + ",".join(map(repr, row)) for i, row in enumerate(values)]
    atomic_write(path, lambda fh: fh.write(("\n".join(lines) + "\n").encode()), make_folder=False)


def save_weights(path, meas: Measurement) -> None:
    """Write the programmed weights and activation of ``meas`` as a ``.npz`` (atomically)."""
    arrays = {k: v for k, v in meas.arrays().items() if k[:1] in "Wb" or k == "activation"}
    atomic_write(path, lambda fh: np.savez(fh, **arrays), make_folder=False)


def save_file(path, meas: Measurement, *, csv: str = "wide") -> str | None:
    """Write ``meas`` in the format its extension names: ``.npz``, netCDF / HDF5
    (:data:`NETCDF_EXTENSIONS`) or ``.csv`` (``csv="wide"`` or ``"long"``; the weights then go
    to ``STEM.weights.npz``, whose path is returned). Atomic; raises GiftInputError on an
    unknown extension before anything is written."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    require(ext in (".npz", ".csv") + NETCDF_EXTENSIONS,
            f"{path}: unknown extension {ext or '(none)'!r}; write .npz, .csv or netCDF "
            f"({', '.join(NETCDF_EXTENSIONS)})")
    require(csv in ("wide", "long"), f"csv layout {csv!r}: wide or long")
    if ext == ".npz":
        save_measurement(path, meas)
        return None
    if ext in NETCDF_EXTENSIONS:
        save_netcdf(path, meas)
        return None
    folder = os.path.dirname(os.path.abspath(path))
    require(os.path.isdir(folder), f"{path}: folder {folder} does not exist")
    wpath = os.path.splitext(path)[0] + ".weights.npz"
    (save_wide_csv if csv == "wide" else save_csv)(path, meas)
    save_weights(wpath, meas)
    return wpath


def load_weight_arrays(path) -> dict:
    """The raw arrays W1..WL, b1..bL (and ``activation``) of a measurement's weights ``.npz``,
    checked to exist -- what the CSV and table readers pair with their values.
    (:func:`gift_theory.training.load_weights` reads a trained network: ``(params, meta)``.)"""
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
    warrays = load_weight_arrays(weights)
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
                                              fmt=["%d", "%d", "%d", "%d", "%.17g"] + (["%.17g"] if meas.t is not None else [])),
                 make_folder=False)


def save_measurement(path, meas: Measurement) -> None:
    """Write ``meas`` as a reference §3 ``.npz`` (atomically)."""
    arrays = meas.arrays()
    atomic_write(path, lambda fh: np.savez(fh, **arrays), make_folder=False)
