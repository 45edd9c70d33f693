"""Reader for the standard MNIST IDX files (LeCun's format), from a folder the user names."""

from __future__ import annotations

import gzip
import os

import numpy as np

from .._errors import GiftInputError
from ._types import Dataset, one_hot

FILES = {
    "train_images": "train-images-idx3-ubyte",
    "train_labels": "train-labels-idx1-ubyte",
    "test_images": "t10k-images-idx3-ubyte",
    "test_labels": "t10k-labels-idx1-ubyte",
}

_DTYPES = {0x08: np.uint8, 0x09: np.int8, 0x0B: ">i2", 0x0C: ">i4", 0x0D: ">f4", 0x0E: ">f8"}


def read_idx(path: str) -> np.ndarray:
    """Read one IDX file (plain or .gz). Raises :class:`GiftInputError` if malformed."""
    opener = gzip.open if path.endswith(".gz") else open
    try:
        with opener(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise GiftInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(data) < 4 or data[0] != 0 or data[1] != 0 or data[2] not in _DTYPES:
        raise GiftInputError(f"{path}: not an IDX file (bad magic number)")
    ndim = data[3]
    header = 4 + 4 * ndim
    if ndim == 0 or len(data) < header:
        raise GiftInputError(f"{path}: truncated IDX header")
    shape = tuple(int.from_bytes(data[4 + 4 * i: 8 + 4 * i], "big") for i in range(ndim))
    dtype = np.dtype(_DTYPES[data[2]])
    expected = int(np.prod(shape)) * dtype.itemsize
    if len(data) - header != expected:
        raise GiftInputError(f"{path}: IDX header says shape {shape} ({expected} bytes) but the file holds "
                             f"{len(data) - header} bytes")
    return np.frombuffer(data, dtype=dtype, offset=header).reshape(shape)


def _find(folder: str, stem: str) -> str:
    for name in (stem, stem + ".gz", stem.replace("-idx", ".idx"), stem.replace("-idx", ".idx") + ".gz"):
        p = os.path.join(folder, name)
        if os.path.isfile(p):
            return p
    raise GiftInputError(f"{folder}: no file {stem} (or {stem}.gz) -- expected the four standard MNIST IDX files")


def load_mnist_folder(folder: str):
    """The full MNIST (60000 / 10000) from IDX files in ``folder``, scaled to [0, 1]."""

    if not os.path.isdir(folder):
        raise GiftInputError(f"{folder}: no such folder (expected the MNIST IDX files there)")
    arrays = {k: read_idx(_find(folder, v)) for k, v in FILES.items()}
    for split in ("train", "test"):
        img, lab = arrays[f"{split}_images"], arrays[f"{split}_labels"]
        if img.ndim != 3 or lab.ndim != 1 or img.shape[0] != lab.shape[0]:
            raise GiftInputError(f"{folder}: {split} images {img.shape} and labels {lab.shape} do not match")
        if lab.size and (lab.min() < 0 or lab.max() > 9):
            raise GiftInputError(f"{folder}: {split} labels outside 0..9")
    xtr = arrays["train_images"].reshape(arrays["train_images"].shape[0], -1).astype(np.float32) / 255.0
    xte = arrays["test_images"].reshape(arrays["test_images"].shape[0], -1).astype(np.float32) / 255.0
    ltr = arrays["train_labels"].astype(np.int64)
    lte = arrays["test_labels"].astype(np.int64)
    return Dataset("mnist", xtr, one_hot(ltr, 10), ltr, xte, one_hot(lte, 10), lte,
                   {"source": os.path.abspath(folder), "scaling": "pixel / 255"})


def write_idx(path: str, array: np.ndarray) -> None:
    """Write ``array`` (uint8) as an IDX file -- for tests and for users making small sets."""
    array = np.ascontiguousarray(array, dtype=np.uint8)
    header = bytes([0, 0, 0x08, array.ndim]) + b"".join(int(n).to_bytes(4, "big") for n in array.shape)
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "wb") as fh:
        fh.write(header + array.tobytes())
