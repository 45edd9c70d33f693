"""One measurement campaign (reference §3): what a chip returns and what a measurement file holds.

The one type for both: :meth:`gift_theory.chips.Chip.measure` returns it (``params`` are the
weights the chip was programmed with), :mod:`gift_theory.lab` reads it from and writes it to
``.npz``, long or wide ``.csv`` and netCDF / HDF5 files; :meth:`Measurement.to_xarray` and
:meth:`Measurement.from_xarray` convert it to and from an ``xarray.Dataset`` (reference §3).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._arch import Architecture


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
        from .lab._io import dataset_arrays, validate_arrays, weights_arrays

        arrays = dataset_arrays(ds, where)
        if "W1" not in arrays and weights is not None:
            arrays = {**weights_arrays(weights), **arrays}
        return validate_arrays(arrays, where=where)
