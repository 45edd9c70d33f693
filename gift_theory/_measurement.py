"""One measurement campaign (reference §3): what a chip returns and what a measurement file holds.

The one type for both: :meth:`gift_theory.chips.Chip.measure` returns it (``params`` are the
weights the chip was programmed with), :mod:`gift_theory.lab` reads it from and writes it to
``.npz``, long or wide ``.csv`` and netCDF / HDF5 files; :meth:`Measurement.to_xarray` and
:meth:`Measurement.from_xarray` convert it to and from an ``xarray.Dataset`` (reference §3);
:func:`validate_arrays` builds it from the reference §3 arrays, checking every rule.
"""

from __future__ import annotations

import dataclasses
import os
import re
import stat

import numpy as np

from ._arch import ACTIVATIONS, Architecture
from ._errors import GiftInputError, require
from ._io import NPZ_READ_ERRORS
from ._params import Layer


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One campaign: inputs, repeated shots, optional taps and times, programmed weights.

    Attributes
    ----------
    x : ndarray of shape (n, d_0)
    y : ndarray of shape (n, r, d_L)
    taps : tuple of L-1 ndarrays of shape (n, r, d_l), or None (no taps measured)
    params : tuple of Layer (W_l (d_l, d_{l-1}), b_l (d_l,)) as numpy arrays
    t : ndarray of shape (n, r) or None
    activation : str
    """

    x: np.ndarray
    y: np.ndarray
    params: tuple
    taps: tuple | None = None
    t: np.ndarray | None = None
    activation: str = "tanh"

    @property
    def n(self) -> int:
        return int(self.x.shape[0])

    @property
    def r(self) -> int:
        return int(self.y.shape[1])

    @property
    def arch(self) -> Architecture:
        widths = (int(self.params[0].W.shape[1]),) + tuple(int(p.W.shape[0]) for p in self.params)
        return Architecture(widths, self.activation)

    @property
    def has_taps(self) -> bool:
        return self.taps is not None

    def layers(self) -> tuple[np.ndarray, ...]:
        """The measured layer outputs: taps a_1..a_{L-1} (if any) then y; each (n, r, d_l)."""
        return (tuple(self.taps) if self.taps is not None else ()) + (self.y,)

    def layer_ids(self) -> tuple[int, ...]:
        """The 1-based layer number of each entry of :meth:`layers`."""
        L = len(self.params)
        return tuple(range(1, L)) + (L,) if self.taps is not None else (L,)

    def subset(self, idx) -> "Measurement":
        """The same campaign restricted to the inputs ``idx``."""
        idx = np.asarray(idx)
        return dataclasses.replace(
            self, x=self.x[idx], y=self.y[idx],
            taps=None if self.taps is None else tuple(a[idx] for a in self.taps),
            t=None if self.t is None else self.t[idx])

    def arrays(self) -> dict[str, np.ndarray]:
        """The reference §3 dictionary of this measurement."""
        out = {"x": self.x, "y": self.y, "activation": np.array(self.activation)}
        for l, (W, b) in enumerate(self.params, start=1):
            out[f"W{l}"] = np.asarray(W)
            out[f"b{l}"] = np.asarray(b)
        if self.taps is not None:
            for l, a in enumerate(self.taps, start=1):
                out[f"a{l}"] = a
        if self.t is not None:
            out["t"] = self.t
        return out

    def to_xarray(self):
        """This campaign as an ``xarray.Dataset`` with the reference §3 names.

        Variables ``x (input, d0)``, ``y (input, shot, d{L})``, taps ``a{l} (input, shot, d{l})``,
        ``t (input, shot)``, weights ``W{l} (d{l}, d{l-1})`` and ``b{l} (d{l})``; the attribute
        ``activation``. The dimensions ``d0..dL`` are the layer widths of the paper.
        """
        import xarray as xr

        L = len(self.params)
        data = {"x": (("input", "d0"), np.asarray(self.x)), "y": (("input", "shot", f"d{L}"), np.asarray(self.y))}
        for l, (W, b) in enumerate(self.params, start=1):
            data[f"W{l}"] = ((f"d{l}", f"d{l - 1}"), np.asarray(W))
            data[f"b{l}"] = ((f"d{l}",), np.asarray(b))
        if self.taps is not None:
            for l, a in enumerate(self.taps, start=1):
                data[f"a{l}"] = (("input", "shot", f"d{l}"), np.asarray(a))
        if self.t is not None:
            data["t"] = (("input", "shot"), np.asarray(self.t))
        return xr.Dataset(data, attrs={"activation": self.activation})

    @classmethod
    def from_xarray(cls, ds, *, weights=None, where: str = "dataset") -> "Measurement":
        """The campaign held by an ``xarray.Dataset`` (the inverse of :meth:`to_xarray`), validated.

        ``x`` is read as ``(input, ·)``, ``y``, the taps ``a{l}`` as ``(input, shot, ·)`` and ``t``
        as ``(input, shot)``: dimensions named ``input`` and ``shot`` are moved into place,
        the others are free (a file without those names is read in the order stored).
        ``weights``: a mapping or a ``.npz`` path with ``W1..WL, b1..bL`` (and ``activation``),
        used when the dataset holds no weights. Anything else in the dataset is ignored.

        Raises
        ------
        GiftInputError
            One line naming ``where`` and the problem.
        """
        arrays = dataset_arrays(ds, where)
        if "W1" not in arrays and weights is not None:
            arrays = {**weights_arrays(weights), **arrays}
        return validate_arrays(arrays, where=where)


# ---- the reference §3 arrays, validated into a Measurement -----------------------------------

#: the largest magnitude a float32 holds: gift computes in float32 (:func:`gift_theory.to32`), so a
#: value beyond it is an infinity there, whatever the file's dtype
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _float_array(arrays, key, where):
    a = arrays[key]
    require(a.dtype.kind in "fiu", f"{where}: {key} has dtype {a.dtype}, expected float")
    a = np.asarray(a, dtype=np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        raise GiftInputError(f"{where}: {key} contains NaN or Inf ({float(a[i])!r} at index {list(map(int, i))})")
    with np.errstate(over="ignore"):
        big = ~np.isfinite(a.astype(np.float32))
    if big.any():
        i = np.unravel_index(int(np.argmax(big)), a.shape)
        raise GiftInputError(f"{where}: {key} holds {a[i]:.4g} at index {list(map(int, i))}, beyond float32's range "
                             f"(|v| <= {FLOAT32_MAX:.4g}), the precision gift computes in")
    return a


def _layer_keys(keys, where):
    """L from the keys W1..WL, b1..bL, refusing a gap or an unpaired key (naming the missing one)."""
    num = {c: sorted(int(k[1:]) for k in keys if re.fullmatch(c + r"[1-9]\d*", k)) for c in "Wb"}
    L = max(num["W"] + num["b"], default=0)
    for l in range(1, L + 1):
        for c, other in (("W", "b"), ("b", "W")):
            if l not in num[c]:
                have = [f"{k}{m}" for k in (other, c) for m in num[k] if m >= l and f"{k}{m}" != f"{c}{l}"]
                raise GiftInputError(f"{where}: has {have[0]} but no {c}{l} (a network needs W1..W{L} and "
                                     f"b1..b{L})")
    return L


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
    L = _layer_keys(keys, where)
    params = []
    for l in range(1, L + 1):
        W = _float_array(arrays, f"W{l}", where)
        b = _float_array(arrays, f"b{l}", where)
        require(W.ndim == 2, f"{where}: W{l} has shape {W.shape}, expected a matrix (d_{l}, d_{l - 1})")
        d_in = d0 if l == 1 else params[-1].W.shape[0]
        require(W.shape[1] == d_in, f"{where}: W{l} has shape {W.shape} but its input width is {d_in}"
                + (" (the width of x)" if l == 1 else f" (the rows of W{l - 1})"))
        require(b.shape == (W.shape[0],), f"{where}: b{l} has shape {b.shape}, W{l} needs ({W.shape[0]},)")
        params.append(Layer(W, b))
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
        act = np.asarray(arrays["activation"])
        activation = act.item() if act.dtype.kind in "USO" and act.size == 1 else None
        if isinstance(activation, bytes):  # a string stored as bytes (numpy's "S" dtype, h5py)
            try:
                activation = activation.decode("utf-8")
            except UnicodeDecodeError:
                activation = None
        require(isinstance(activation, str), f"{where}: activation must be a string, got {act!r}")
        require(activation in ACTIVATIONS, f"{where}: unknown activation {activation!r}; known: {', '.join(ACTIVATIONS)}")
    return Measurement(x=x, y=y, params=tuple(params), taps=taps, t=t, activation=activation)


def read_head(path, size: int = 8) -> bytes:
    """The first ``size`` bytes of the regular file ``path``; anything else -- no file, a folder, a
    FIFO or a device (which would block or never end), an unreadable file -- is a bad input."""
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise GiftInputError(f"{path}: no such file" if isinstance(exc, FileNotFoundError)
                             else f"{path}: cannot be read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = ("a folder" if stat.S_ISDIR(st.st_mode) else "a pipe (FIFO)" if stat.S_ISFIFO(st.st_mode) else
                "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a plain file")
        raise GiftInputError(f"{path}: is {kind}, not a file to read" if kind != "not a plain file"
                             else f"{path}: not a regular file")
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError as exc:
        raise GiftInputError(f"{path}: cannot be read ({exc.strerror})") from None


def _npz_arrays(path, what: str, keep=None) -> dict:
    """The arrays of an .npz (those ``keep`` accepts), never unpickled; a damaged archive or an array
    too large to hold is a bad input."""
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as f:  # our handle: closed on a bad file
            return {k: f[k] for k in f.files if keep is None or keep(k)}
    except MemoryError:
        raise GiftInputError(f"{path}: an array in this .npz is too large to load into memory") from None
    except NPZ_READ_ERRORS as exc:
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GiftInputError(f"{path}: not a readable .npz {what}file ({type(exc).__name__}"
                             f"{': ' + msg if msg else ''})") from None


def load_weight_arrays(path) -> dict:
    """The raw arrays W1..WL, b1..bL (and ``activation``) of a measurement's weights ``.npz``,
    checked to exist -- what the CSV and table readers pair with their values.
    (:func:`gift_theory.training.load_weights` reads a trained network: ``(params, meta)``.)"""
    path = os.fspath(path)
    head = read_head(path)
    require(head.startswith(b"PK"), f"{path}: not an .npz weights file (an .npz is a zip archive; this file "
                                    f"starts with {head[:8]!r})")
    arrays = _npz_arrays(path, "weights ", keep=lambda k: (k[:1] in "Wb" and k[1:].isdigit()) or k == "activation")
    require("W1" in arrays, f"{path}: no weights (expected keys W1, b1, ...)")
    return arrays


def weights_arrays(weights) -> dict:
    """W1..WL, b1..bL (and ``activation``) from a ``.npz`` path or a mapping of arrays."""
    if isinstance(weights, (str, os.PathLike)):
        return load_weight_arrays(weights)
    return {k: np.asarray(v) for k, v in dict(weights).items() if (k[:1] in "Wb" and k[1:].isdigit()) or k == "activation"}


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
