"""Data sets: fixed splits, documented scaling, the IDX reader and its errors."""

import os

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import gift_theory as gt
from gift_theory.data import Teacher, load_dataset, load_mnist_folder, read_idx, write_idx


def test_digits_fixed_split_and_scaling():
    a, b = load_dataset("digits"), load_dataset("digits")
    assert a.x_train.shape == (1437, 64) and a.x_test.shape == (360, 64)
    assert np.array_equal(a.x_test, b.x_test) and np.array_equal(a.labels_train, b.labels_train)
    assert 0.0 <= a.x_train.min() and a.x_train.max() <= 1.0
    assert np.array_equal(a.y_train.argmax(1), a.labels_train) and np.allclose(a.y_train.sum(1), 1)


@pytest.mark.slow
def test_mnist5k():
    d = load_dataset("mnist5k")
    assert d.x_train.shape == (4000, 784) and d.x_test.shape == (1000, 784) and d.y_train.shape == (4000, 10)
    assert d.x_train.max() <= 1.0 and set(np.unique(d.labels_test)) == set(range(10))


def test_teacher_fresh_samples_and_fixed_labeller():
    import jax

    t = Teacher(widths=(3, 5, 2), seed=4)
    x1, y1 = t.sample(jax.random.PRNGKey(0), 100)
    x2, y2 = t.sample(jax.random.PRNGKey(1), 100)
    assert not np.allclose(x1, x2)
    np.testing.assert_allclose(t.label(x1), y1, rtol=1e-6)
    assert not np.allclose(Teacher(widths=(3, 5, 2), seed=5).label(x1), y1)


def make_mnist_folder(folder, n_train=20, n_test=10, gz=False):
    rng = np.random.default_rng(0)
    ext = ".gz" if gz else ""
    write_idx(os.path.join(folder, "train-images-idx3-ubyte" + ext), rng.integers(0, 256, (n_train, 28, 28)))
    write_idx(os.path.join(folder, "train-labels-idx1-ubyte" + ext), rng.integers(0, 10, n_train))
    write_idx(os.path.join(folder, "t10k-images-idx3-ubyte" + ext), rng.integers(0, 256, (n_test, 28, 28)))
    write_idx(os.path.join(folder, "t10k-labels-idx1-ubyte" + ext), rng.integers(0, 10, n_test))


@pytest.mark.parametrize("gz", [False, True])
def test_mnist_idx_folder(tmp_path, gz):
    make_mnist_folder(str(tmp_path), gz=gz)
    d = load_dataset("mnist", folder=str(tmp_path))
    assert d.x_train.shape == (20, 784) and d.x_test.shape == (10, 784) and d.x_train.max() <= 1.0


def test_mnist_folder_errors(tmp_path):
    with pytest.raises(gt.GiftInputError, match="no such folder"):
        load_mnist_folder(str(tmp_path / "nope"))
    with pytest.raises(gt.GiftInputError, match="train-images"):
        load_mnist_folder(str(tmp_path))
    make_mnist_folder(str(tmp_path))
    (tmp_path / "t10k-labels-idx1-ubyte").write_bytes(b"\x00\x00\x08\x01\x00\x00\x00\x05abc")
    with pytest.raises(gt.GiftInputError, match="t10k-labels"):
        load_mnist_folder(str(tmp_path))
    with pytest.raises(gt.GiftInputError, match="folder"):
        load_dataset("mnist")
    with pytest.raises(gt.GiftInputError, match="unknown dataset"):
        load_dataset("cifar")


@given(arr=hnp.arrays(np.uint8, hnp.array_shapes(min_dims=1, max_dims=3, max_side=6)))
def test_idx_round_trip(tmp_path_factory, arr):
    path = str(tmp_path_factory.mktemp("idx") / "a-idx-ubyte")
    write_idx(path, arr)
    np.testing.assert_array_equal(read_idx(path), arr)


@given(data=st.binary(max_size=64))
def test_idx_reader_never_crashes_on_garbage(tmp_path_factory, data):
    path = str(tmp_path_factory.mktemp("idx") / "g")
    with open(path, "wb") as fh:
        fh.write(data)
    try:
        out = read_idx(path)
    except gt.GiftInputError as exc:
        assert "\n" not in str(exc) and path in str(exc)
    else:
        assert isinstance(out, np.ndarray)
