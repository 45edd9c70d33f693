"""In-silico training: eq. projected-sgd, the mini-batch practice, the cache."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.data import Teacher, load_dataset
from gift_theory.training import (TrainConfig, load_or_train, load_weights, projected_sgd, robbins_monro,
                                  save_weights, train, train_with_history)


def test_robbins_monro_steps_satisfy_A4():
    k = np.arange(1, 2_000_001, dtype=np.float64)
    for gamma in (0.6, 0.75, 1.0):
        eps = robbins_monro(k, 0.5, 100.0, gamma)
        # partial sums of eps grow without bound (like n^(1-gamma) or log n), those of eps^2 converge
        assert eps[: len(k) // 2].sum() < eps.sum() - 0.1
        tail_sq = (robbins_monro(k[-1] + 1, 0.5, 100.0, gamma) ** 2) * k[-1] / (2 * gamma - 1)
        assert (eps ** 2).sum() + tail_sq < 10.0
    with pytest.raises(gt.GiftInputError):
        TrainConfig(gamma=0.5)


def teacher_sampler_factory():
    t = Teacher(widths=(3, 4, 2), seed=1)
    return t


class TeacherSampler:
    """Fresh draws from the teacher: the data distribution mu itself."""

    def __init__(self, teacher):
        self.t = teacher

    def __call__(self, key):
        x, y = self.t.sample(key, 1)
        return x[0], y[0]

    def __hash__(self):
        return hash(self.t)

    def __eq__(self, other):
        return isinstance(other, TeacherSampler) and other.t == self.t


@pytest.mark.slow
def test_projected_sgd_stays_in_the_box_and_lowers_J():
    t = teacher_sampler_factory()
    arch = gt.Architecture((3, 4, 2))
    box = gt.Box(-0.3, 0.3, -0.2, 0.2)
    cfg = TrainConfig(method="projected_sgd", steps=3000, eps0=0.2, k0=50.0, gamma=0.75, box=box)
    p0 = gt.init_params(jax.random.PRNGKey(0), arch, gain=3.0)
    p, losses = projected_sgd(jax.random.PRNGKey(1), p0, TeacherSampler(t), gt.awgn(0.1), arch, cfg)
    for W, b in p:
        f = np.float32  # the box's bounds as the float32 weights hold them
        assert W.min() >= f(box.W_min) and W.max() <= f(box.W_max)
        assert b.min() >= f(box.b_min) and b.max() <= f(box.b_max)
    assert any(float(jnp.abs(W).max()) == pytest.approx(0.3) for W, _ in p)  # the box binds here
    x, y = t.sample(jax.random.PRNGKey(9), 4000)
    before = gt.objective(jax.random.PRNGKey(2), gt.project(p0, box), x, y, gt.awgn(0.1), arch, K2=2)
    after = gt.objective(jax.random.PRNGKey(2), p, x, y, gt.awgn(0.1), arch, K2=2)
    assert float(after.mean) + 4.5 * float(after.se) < float(before.mean)
    assert losses.shape == (3000,)


def test_same_seed_same_weights():
    ds = load_dataset("teacher", widths=(3, 4, 2), n_train=256, n_test=64)
    arch = gt.Architecture((3, 5, 2))
    cfg = TrainConfig(epochs=3, batch_size=16, lr=0.05)
    a = train(jax.random.PRNGKey(0), arch, ds.x_train, ds.y_train, gt.awgn(0.1), cfg)
    b = train(jax.random.PRNGKey(0), arch, ds.x_train, ds.y_train, gt.awgn(0.1), cfg)
    c = train(jax.random.PRNGKey(1), arch, ds.x_train, ds.y_train, gt.awgn(0.1), cfg)
    assert all(np.array_equal(np.asarray(u.W), np.asarray(v.W)) for u, v in zip(a, b))
    assert not np.array_equal(np.asarray(a[0].W), np.asarray(c[0].W))


def test_optax_variant_trains():
    ds = load_dataset("teacher", widths=(3, 4, 2), n_train=512, n_test=64)
    arch = gt.Architecture((3, 6, 2))
    p, hist = train_with_history(jax.random.PRNGKey(0), arch, ds.x_train, ds.y_train, gt.awgn(0.05),
                                 TrainConfig(method="optax", optimizer="adam", lr=0.01, epochs=20, batch_size=32))
    assert hist[-1] < 0.5 * hist[0]


@pytest.mark.slow
def test_digits_training_quality():
    """Noise-aware training at s0 = 0.1 on digits (shortened recipe) gives > 90 % test accuracy."""
    ds = load_dataset("digits")
    arch = gt.Architecture((64, 32, 32, 10))
    p = train(jax.random.PRNGKey(0), arch, ds.x_train, ds.y_train, gt.awgn(0.1),
              TrainConfig(epochs=25, lr=0.05, momentum=0.9, batch_size=32))
    acc = gt.accuracy(jax.random.PRNGKey(1), p, ds.x_test, ds.labels_test, gt.awgn(0.1), arch, K2=4)
    assert float(acc.mean) > 0.90


@pytest.mark.slow
def test_cache_reuses_and_writes_atomically(tmp_path):
    arch = gt.Architecture((4, 5, 2))  # the default teacher is 4 -> 2
    cfg = TrainConfig(epochs=2, batch_size=64)
    kw = dict(config=cfg, cache=str(tmp_path), progress=False)
    p1, info1 = load_or_train("teacher", arch, 0.1, 0, **kw)
    p2, info2 = load_or_train("teacher", arch, 0.1, 0, **kw)
    assert not info1["cached"] and info2["cached"] and info1["path"] == info2["path"]
    assert all(np.array_equal(np.asarray(a.W), np.asarray(b.W)) for a, b in zip(p1, p2))
    _, info3 = load_or_train("teacher", arch, 0.2, 0, **kw)
    assert info3["path"] != info1["path"]
    assert [f for f in os.listdir(tmp_path) if f.startswith(".tmp")] == []
    params, meta = load_weights(info1["path"])
    assert meta["s0"] == 0.1 and meta["arch"] == "4-5-2" and meta["dataset"] == "teacher"
    with pytest.raises(gt.GiftInputError):
        load_or_train("teacher", gt.Architecture((3, 4, 2)), 0.1, 0, **kw)


def test_weight_file_round_trip_and_bad_files(tmp_path):
    arch = gt.Architecture((3, 4, 2))
    p = gt.init_params(jax.random.PRNGKey(0), arch)
    path = str(tmp_path / "w.npz")
    save_weights(path, p, {"note": "x"})
    q, meta = load_weights(path)
    assert meta == {"note": "x"}
    gt.check_params(q, arch)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(gt.GiftInputError, match="bad.npz"):
        load_weights(str(bad))
    np.savez(tmp_path / "mismatch.npz", W1=np.zeros((4, 3)), b1=np.zeros(4), W2=np.zeros((2, 5)), b2=np.zeros(2))
    with pytest.raises(gt.GiftInputError, match="W2"):
        load_weights(str(tmp_path / "mismatch.npz"))
    with pytest.raises(gt.GiftInputError, match="b2"):
        gt.check_params([(np.zeros((4, 3)), np.zeros(4)), (np.zeros((2, 4)), np.zeros(3))], arch)
