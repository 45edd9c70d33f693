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

import gc
import os
import re
import sys

import numpy as np

from .._errors import GiftInputError, require
from .._io import atomic_write
from .._measurement import (
    Measurement,
    _layer_keys,
    _npz_arrays,
    dataset_arrays,
    load_weight_arrays,
    read_head,
    validate_arrays,
    weights_arrays,
)


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
    head = read_head(path)
    for magic, fmt in _MAGIC.items():
        if head.startswith(magic):
            return fmt
    ext = os.path.splitext(path)[1].lower()
    if head.startswith(b"\x93NUMPY"):
        raise GiftInputError(f"{path}: a single .npy array, not a measurement (an .npz with x, y, W1.., b1..)")
    if ext == ".npz":
        raise GiftInputError(f"{path}: not an .npz file (an .npz is a zip archive; this file starts with "
                             f"{head[:8]!r})")
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
    arrays = _npz_arrays(path, "")
    if weights is not None:
        w = load_weight_arrays(weights)
        arrays = {**w, **arrays}
    return validate_arrays(arrays, where=path)


def _needs_weights(path, arrays, weights):
    if "W1" in arrays:
        return arrays
    require(weights is not None, f"{path}: holds no weights (W1, b1, ...): give --weights FILE.npz")
    return {**weights_arrays(weights), **arrays}


def load_netcdf(path, *, weights=None) -> Measurement:
    """A netCDF (3 or 4) or plain HDF5 file read through xarray; see :meth:`Measurement.from_xarray`."""
    import xarray as xr

    path = os.fspath(path)
    engine = "scipy" if detect_format(path) == "netcdf3" else "h5netcdf"
    kw = {"phony_dims": "sort"} if engine == "h5netcdf" else {}  # plain HDF5 has no dimension names
    if engine == "h5netcdf":
        damage = global_heap_damage(path)
        if damage is not None:
            raise GiftInputError(f"{path}: not a readable netCDF / HDF5 file ({damage})")
    hook, failure = sys.unraisablehook, None
    try:
        with xr.open_dataset(path, engine=engine, mask_and_scale=False, decode_times=False, **kw) as ds:
            arrays = dataset_arrays(ds.load(), where=path)
    except GiftInputError:
        raise
    except Exception as exc:  # h5py / scipy raise many kinds on a damaged file
        failure = (f"{path}: not a readable netCDF / HDF5 file ({type(exc).__name__}: "
                   f"{str(exc).splitlines()[0] if str(exc) else ''})")
        sys.unraisablehook = _quiet_half_open(hook)
    if failure is not None:
        try:  # the half-opened h5netcdf File is collected here, before the one-line error
            gc.collect()
        finally:
            sys.unraisablehook = hook
        raise GiftInputError(failure) from None
    return validate_arrays(_needs_weights(path, arrays, weights), where=path)


def global_heap_damage(path) -> str | None:
    """What is wrong with the HDF5 global heap collections of ``path`` (None: nothing found).

    A collection (signature ``GCOL``, version 1) holds the variable-length data -- netCDF-4 keeps
    each variable's dimension list there -- as objects of a 16-byte header (index, references,
    size) and the data padded to 8 bytes; the last may be the free space (index 0), whose size
    counts its header. It carries no checksum, and the HDF5 library parses it without bounds: a
    free-space object of size 0 before the collection's end makes it loop forever, an object that
    runs past the end makes it read past its buffer. Such a collection is found here, by walking
    every collection's objects, before the library reads the file.
    """
    import mmap
    import struct

    with open(path, "rb") as fh:
        try:
            data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError:  # an empty file: nothing to walk (the library refuses it)
            return None
    with data:
        start = 0
        while (at := data.find(b"GCOL\x01\x00\x00\x00", start)) >= 0:
            start = at + 4
            if at + 16 > len(data):
                return f"a global heap collection at byte {at} is cut off by the file's end"
            size, = struct.unpack_from("<Q", data, at + 8)
            end = at + size
            if size < 4096 or end > len(data):
                return (f"the global heap collection at byte {at} claims {size} bytes (at least 4096, "
                        f"and the file has {len(data) - at} from there)")
            p = at + 16
            while p + 16 <= end:
                index, = struct.unpack_from("<H", data, p)
                length, = struct.unpack_from("<Q", data, p + 8)
                step = length if index == 0 else 16 + -(-length // 8) * 8
                if step == 0 or p + step > end:
                    what = "its free space" if index == 0 else f"its object {index}"
                    return (f"the global heap collection at byte {at}: {what}, at byte {p}, has size {length}, which "
                            + ("does not reach past its own header" if step == 0 else
                               f"runs past the collection's end at byte {end}"))
                p += step
    return None


def _quiet_half_open(hook):
    """An unraisable hook that drops h5netcdf's File.close failing on a File whose opening failed
    (it has no ``_writable`` yet: 'Exception ignored in File.close' on stderr after the one-line
    error) and passes everything else to ``hook``."""
    def quiet(u):
        if isinstance(u.exc_value, AttributeError) and "h5netcdf" in getattr(u.object, "__module__", ""):
            return None
        return hook(u)
    return quiet


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


class _Table:
    """A CSV's columns by lower-case name, read once as float64 (pandas' C parser: compact and
    fast); a cell that is not a finite number is named by its line, its text read back then."""

    def __init__(self, path, kind: str):
        import csv

        import pandas as pd

        self.path = path
        read_head(path)  # a regular file, not a FIFO or a device
        try:
            with open(path, newline="", encoding="utf-8-sig") as fh:
                header = next(csv.reader(fh), None)
        except (OSError, UnicodeDecodeError) as exc:
            raise GiftInputError(f"{path}: not a readable CSV ({type(exc).__name__})") from None
        require(header, f"{path}: empty (a {kind} CSV needs a header row)")
        cols = [h.strip().lower() for h in header]
        dup = sorted({c for c in cols if cols.count(c) > 1})
        require(not dup, f"{path}: column {dup[0] if dup else ''!r} appears twice")
        self.cols = cols
        kw = dict(skipinitialspace=True, encoding="utf-8-sig", header=0, names=cols)
        try:
            self.df = pd.read_csv(path, dtype=np.float64, **kw)
            self.text = None
        except (ValueError, TypeError):  # some cell is not a number: read as text to name it
            self.df = None
        except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            raise GiftInputError(f"{path}: not a readable CSV ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
        self.numeric = self.df is not None
        if self.df is None:
            self.df = self._strings(kw)
        self.rows = len(self.df)
        require(self.rows > 0, f"{path}: no data rows (only a header)")

    def _strings(self, kw):
        import pandas as pd

        try:
            df = pd.read_csv(self.path, dtype=str, keep_default_na=False, **kw)
        except (OSError, ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            raise GiftInputError(f"{self.path}: not a readable CSV ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
        return df

    def _raw(self, c, k) -> str:
        if not self.numeric:
            return str(self.df[c].iloc[k]).strip()
        if self.text is None:
            self.text = self._strings(dict(skipinitialspace=True, encoding="utf-8-sig", header=0, names=self.cols))
        return str(self.text[c].iloc[k]).strip()

    def numbers(self, c, integer: bool = False, low=None):
        """Column ``c`` as float64, every cell a finite number (``integer``: an integer >= ``low``)."""
        col = self.df[c]
        if not self.numeric:
            raw = col.str.strip()
            try:  # numpy parses decimal strings exactly (the shortest repr reads back to the same float)
                v = raw.to_numpy().astype(np.float64)
            except ValueError:
                v = np.array([_float_or_nan(u) for u in raw.tolist()])
        else:
            v = col.to_numpy(np.float64)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            k = int(bad[0])
            raw = self._raw(c, k)
            what = "is empty" if raw == "" else f"is not a finite number ({raw!r})"
            inp = self._raw("input", k) if c != "input" and "input" in self.cols else "?"
            raise GiftInputError(f"{self.path}: line {k + 2} (input {inp}): column {c} {what}")
        if integer:
            bad = np.flatnonzero((v != np.round(v)) | ((v < low) if low is not None else False))
            if bad.size:
                k = int(bad[0])
                lim = "" if low is None else f" >= {low}"
                raise GiftInputError(f"{self.path}: line {k + 2}: column {c} must hold integers{lim} (got "
                                     f"{self._raw(c, k)!r})")
        return v


def _grid(path, inp, shot, what: str, lines=None):
    """The (input, shot) grid of rows sorted by (input, shot): inputs numbered consecutively, every
    input holding every shot, no pair twice -- the wide CSV's rules, with every index bounded by
    the rows there are before anything is allocated. Returns (order, ids, shots)."""
    lines = np.arange(len(inp)) if lines is None else lines
    order = np.lexsort((shot, inp))
    si, ss = inp[order], shot[order]
    ids = np.unique(si)
    gap = np.flatnonzero(np.diff(ids) > 1)
    if gap.size:
        raise GiftInputError(f"{path}: input {int(ids[gap[0]]) + 1} has no rows{what} (inputs are numbered "
                             f"consecutively from {int(ids[0])} to {int(ids[-1])})")
    same = np.flatnonzero((np.diff(si) == 0) & (np.diff(ss) == 0))
    if same.size:
        k = int(same[0])
        raise GiftInputError(f"{path}: input {int(si[k])} shot {int(ss[k])} appears twice{what} "
                             f"(lines {_line_of(lines[order], k)} and {_line_of(lines[order], k + 1)})")
    shots = np.unique(ss)
    n, r = len(ids), len(shots)
    if len(si) != n * r:
        counts = np.bincount(si - ids[0], minlength=n)
        i = int(np.argmin(counts))
        have = set(ss[si == ids[i]].tolist())
        miss = [int(s) for s in shots if int(s) not in have]
        raise GiftInputError(f"{path}: input {int(ids[i])} misses shot {miss[0]}{what} ({counts[i]} of the {r} shots "
                             f"{int(shots[0])}..{int(shots[-1])} the file holds; every input needs every shot)")
    return order, ids, shots


def _same_on_every_row(path, values, group, label, lines, between: str = "its rows"):
    """Refuse rows of one group (sorted by group) whose ``values`` differ: ``label(g, j)`` names it."""
    if values.ndim == 1:
        values = values[:, None]
    differs = np.flatnonzero(np.any(values[1:] != values[:-1], axis=1) & (group[1:] == group[:-1]))
    if differs.size:
        k = int(differs[0])
        j = int(np.argmax(values[k + 1] != values[k]))
        raise GiftInputError(f"{path}: {label(int(group[k]), j)} differs between {between} ({float(values[k, j])!r} on "
                             f"line {int(lines[k]) + 2}, {float(values[k + 1, j])!r} on line {int(lines[k + 1]) + 2})")


def load_wide_csv(path, *, weights=None) -> Measurement:
    """Wide CSV: one row per (input, shot), columns ``input, shot, x1..x{d_0}, y1..y{d_L}``, an
    optional ``t`` and optional taps ``a{l}_{j}`` (layer l, neuron j, 1-based); any order,
    other columns ignored.

    ``input`` and ``shot`` are integers; inputs are numbered consecutively, every input has
    the same shots, x is the same on every shot of an input. Rows are sorted by (input, shot).
    A bad row is named by its line and its input. Weights come from ``weights`` (a ``.npz``).
    """
    path = os.fspath(path)
    tab = _Table(path, "wide")
    cols = tab.cols
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

    def block(cmap, label):
        require(cmap, f"{path}: no columns {label}1.. (a wide CSV needs x1..x{{d_0}} and y1..y{{d_L}})")
        width = max(cmap)
        missing = [j for j in range(1, width + 1) if j not in cmap]
        require(not missing, f"{path}: has column {label}{width} but not {label}{missing[0] if missing else ''} "
                             f"(columns {label}1..{label}{width} are needed)")
        return np.stack([tab.numbers(cmap[j]) for j in range(1, width + 1)], axis=1)

    inp = tab.numbers("input", integer=True).astype(np.int64)
    shot = tab.numbers("shot", integer=True).astype(np.int64)
    order, ids, shots = _grid(path, inp, shot, "")
    n, r = len(ids), len(shots)
    # rows sorted by (input, shot), every input holding every shot: a plain reshape
    x_rows = block(groups["x"], "x")[order]
    _same_on_every_row(path, x_rows, inp[order], lambda i, j: f"input {i}: x{j + 1}", order,
                       "its shots")
    arrays = {"x": x_rows.reshape(n, r, -1)[:, 0], "y": block(groups["y"], "y")[order].reshape(n, r, -1)}
    for l, cmap in taps.items():
        arrays[f"a{l}"] = block(cmap, f"a{l}_")[order].reshape(n, r, -1)
    if "t" in cols:
        arrays["t"] = tab.numbers("t")[order].reshape(n, r)
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


def load_csv(path, *, weights=None) -> Measurement:
    """Long-format CSV: one row per value, columns ``input, shot, layer, neuron, value``.

    ``layer`` 0 holds the inputs x (one row per input and feature, any shot; repeated rows must
    agree), layers 1..L-1 the taps (all of them or none), layer L the outputs y; neurons are
    numbered from 1 in each layer (x1.. of the wide CSV is neuron 1 of layer 0). The wide CSV's
    rules hold: inputs are numbered consecutively, every input holds every shot of every neuron
    of a layer, no value is given twice. An optional column ``t`` gives the shot's acquisition
    time (the same on every row of an (input, shot); ignored on layer 0). Weights (W1..WL,
    b1..bL) come from the ``weights`` .npz file; columns may appear in any order, a header row
    is required. Every bad row is named by its line.
    """
    path = os.fspath(path)
    require(weights is not None, f"{path}: a CSV measurement needs --weights FILE.npz with W1..WL, b1..bL")
    warrays = load_weight_arrays(weights)
    tab = _Table(path, "long")
    for c in ("input", "shot", "layer", "neuron", "value"):
        require(c in tab.cols, f"{path}: missing column {c!r} (need input, shot, layer, neuron, value)")
    L = _layer_keys(set(warrays), weights)
    widths = [int(np.shape(warrays["W1"])[1])] + [int(np.shape(warrays[f"W{l}"])[0]) for l in range(1, L + 1)]
    inp, shot, layer = (tab.numbers(c, integer=True, low=0).astype(np.int64) for c in ("input", "shot", "layer"))
    neuron = tab.numbers("neuron", integer=True, low=1).astype(np.int64)
    value = tab.numbers("value")
    t = tab.numbers("t") if "t" in tab.cols else None
    big = np.flatnonzero(layer > L)
    require(not big.size, f"{path}: line {int(big[0]) + 2 if big.size else 0}: layer "
                          f"{int(layer[big[0]]) if big.size else 0}, but the weights {weights} have {L} layers")
    width = np.asarray(widths)[layer]
    wide = np.flatnonzero(neuron > width)
    if wide.size:
        k = int(wide[0])
        raise GiftInputError(f"{path}: line {k + 2}: layer {int(layer[k])} neuron {int(neuron[k])}, but the layer has "
                             f"{int(width[k])} neurons (numbered from 1)")
    rows = np.arange(tab.rows)
    out_rows = rows[layer == L]
    require(out_rows.size, f"{path}: no rows of the output layer {L}")
    arrays = dict(warrays)
    n = r = None
    ids = shots = None
    for l in range(1, L + 1):
        sel = rows[layer == l]
        if not sel.size:
            continue
        d = widths[l]
        # sorted by (input, shot, neuron): each (input, shot) pair must hold its d neurons once
        order = np.lexsort((neuron[sel], shot[sel], inp[sel]))
        s_sel = sel[order]
        dup = np.flatnonzero((np.diff(inp[s_sel]) == 0) & (np.diff(shot[s_sel]) == 0) & (np.diff(neuron[s_sel]) == 0))
        if dup.size:
            k = int(dup[0])
            raise GiftInputError(f"{path}: layer {l}: input {int(inp[s_sel[k]])} shot {int(shot[s_sel[k]])} neuron "
                                 f"{int(neuron[s_sel[k]])} appears twice (lines {int(s_sel[k]) + 2} and "
                                 f"{int(s_sel[k + 1]) + 2})")
        starts = np.flatnonzero(np.r_[True, (np.diff(inp[s_sel]) != 0) | (np.diff(shot[s_sel]) != 0)])
        first = s_sel[starts]
        counts = np.diff(np.r_[starts, len(s_sel)])
        short = np.flatnonzero(counts != d)
        if short.size:
            k = first[short[0]]
            have = set(neuron[sel][(inp[sel] == inp[k]) & (shot[sel] == shot[k])].tolist())
            miss = next(j for j in range(1, d + 1) if j not in have)
            raise GiftInputError(f"{path}: layer {l}: input {int(inp[k])} shot {int(shot[k])} misses neuron {miss} "
                                 f"(every (input, shot) needs all {d} neurons)")
        g_order, g_ids, g_shots = _grid(path, inp[first], shot[first], f" in layer {l}", lines=first)
        if ids is None:
            ids, shots = g_ids, g_shots
            n, r = len(ids), len(shots)
        elif not (np.array_equal(g_ids, ids) and np.array_equal(g_shots, shots)):
            raise GiftInputError(f"{path}: layer {l} has inputs {int(g_ids[0])}..{int(g_ids[-1])} x shots "
                                 f"{int(g_shots[0])}..{int(g_shots[-1])}, the layers before it "
                                 f"{int(ids[0])}..{int(ids[-1])} x {int(shots[0])}..{int(shots[-1])}")
        # rows sorted by (input, shot, neuron), each pair holding all d neurons: a plain reshape
        arrays["y" if l == L else f"a{l}"] = value[s_sel].reshape(n, r, d)
        if t is not None:
            tt = t[s_sel].reshape(n, r, d)
            bad = np.argwhere(tt != tt[:, :, :1])
            if bad.size:
                i, s_, j = (int(v) for v in bad[0])
                k0, k1 = s_sel[(i * r + s_) * d], s_sel[(i * r + s_) * d + j]
                raise GiftInputError(f"{path}: input {int(ids[i])} shot {int(shots[s_])}: t differs between its rows "
                                     f"({float(t[k0])!r} on line {int(k0) + 2}, {float(t[k1])!r} on line {int(k1) + 2})")
            if "t" in arrays:
                bad = np.argwhere(arrays["t"] != tt[:, :, 0])
                if bad.size:
                    i, s_ = (int(v) for v in bad[0])
                    raise GiftInputError(f"{path}: input {int(ids[i])} shot {int(shots[s_])}: t differs between "
                                         f"layers (layer {l} has {float(tt[i, s_, 0])!r}, an earlier one {float(arrays['t'][i, s_])!r})")
            arrays["t"] = tt[:, :, 0]
    sel = rows[layer == 0]
    require(sel.size, f"{path}: no rows of layer 0 (the inputs x)")
    d0 = widths[0]
    order = np.lexsort((neuron[sel], inp[sel]))
    s_sel = sel[order]
    key = inp[s_sel] * (d0 + 1) + neuron[s_sel]
    _same_on_every_row(path, value[s_sel], key, lambda g, j: f"input {g // (d0 + 1)}: x{g % (d0 + 1)}", s_sel)
    first = s_sel[np.r_[True, np.diff(key) != 0]]
    stray = np.flatnonzero((inp[first] < ids[0]) | (inp[first] > ids[-1]))
    if stray.size:
        k = int(first[stray[0]])
        raise GiftInputError(f"{path}: line {k + 2}: input {int(inp[k])} has x (layer 0) but no outputs (layer {L})")
    if len(first) != n * d0:
        have = np.zeros((n, d0), bool)
        have[inp[first] - ids[0], neuron[first] - 1] = True
        i, j = (int(v) for v in np.argwhere(~have)[0])
        raise GiftInputError(f"{path}: input {int(ids[i])} has no x{j + 1} (layer 0, neuron {j + 1})")
    arrays["x"] = value[first].reshape(n, d0)
    taps = [f"a{l}" for l in range(1, L) if f"a{l}" in arrays]
    if taps and len(taps) < L - 1:
        missing = next(l for l in range(1, L) if f"a{l}" not in arrays)
        raise GiftInputError(f"{path}: taps are partial: has rows of layer {taps[0][1:]} but none of layer {missing} "
                             f"(give all hidden layers 1..{L - 1} or none)")
    return validate_arrays(arrays, where=path)


def save_csv(path, meas: Measurement) -> None:
    """Write ``meas`` in the long CSV format of :func:`load_csv` (atomically; neurons numbered from 1)."""
    rows = []
    n, r = meas.n, meas.r
    ii, jj = np.meshgrid(np.arange(n), np.arange(meas.x.shape[1]), indexing="ij")
    rows.append(np.stack([ii.ravel(), np.zeros(ii.size), np.zeros(ii.size), jj.ravel() + 1, meas.x.ravel()], 1))
    for l, a in zip(meas.layer_ids(), meas.layers()):
        i, s, k = np.meshgrid(np.arange(n), np.arange(r), np.arange(a.shape[2]), indexing="ij")
        rows.append(np.stack([i.ravel(), s.ravel(), np.full(i.size, l), k.ravel() + 1, a.ravel()], 1))
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
