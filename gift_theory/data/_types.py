"""The data-set type shared by every loader (digits, mnist5k, an IDX folder, the teacher)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Dataset(NamedTuple):
    """A classification (or teacher-regression) data set with a fixed train/test split.

    Attributes
    ----------
    name : str
    x_train : ndarray of shape (n_train, d_0), float32
    y_train : ndarray of shape (n_train, n_classes), float32 one-hot targets (teacher: outputs)
    labels_train : ndarray of shape (n_train,), int
    x_test, y_test, labels_test : the same for the test split
    meta : dict with ``source`` and ``scaling``
    """

    name: str
    x_train: np.ndarray
    y_train: np.ndarray
    labels_train: np.ndarray
    x_test: np.ndarray
    y_test: np.ndarray
    labels_test: np.ndarray
    meta: dict

    @property
    def n_inputs(self) -> int:
        return int(self.x_train.shape[1])

    @property
    def n_outputs(self) -> int:
        return int(self.y_train.shape[1])


def one_hot(labels, n_classes: int) -> np.ndarray:
    labels = np.asarray(labels, dtype=np.int64)
    out = np.zeros((labels.shape[0], n_classes), np.float32)
    out[np.arange(labels.shape[0]), labels] = 1.0
    return out
