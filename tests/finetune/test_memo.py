"""The in-silico memo: a run that differs only in its chip reuses the work at s0, bit for bit,
on disk across processes, and never returns a result for different inputs.

Private names on purpose: the memo's hit and miss counters (``_memo``) and the referee's
per-input scores (``referee_scores``, ``per_input_scores``) are what shows that work is
shared; a public result is the same number whether it was reused or recomputed."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory import _memo
from gift_theory.finetune import direction, finetune_on, make_problem
from gift_theory.finetune._problem import referee_scores

ARCH = gt.Architecture((6, 8, 5, 3))


class _DS:
    def __init__(self, n=200, seed=0):
        k1, k2, k3 = jax.random.split(jax.random.PRNGKey(seed), 3)
        self.x_train = jax.random.normal(k1, (n, ARCH.widths[0]))
        self.labels_train = np.asarray(jax.random.randint(k2, (n,), 0, ARCH.widths[-1]))
        self.y_train = jax.nn.one_hot(self.labels_train, ARCH.widths[-1])
        self.x_test = jax.random.normal(k3, (n // 2, ARCH.widths[0]))
        self.labels_test = self.labels_train[: n // 2]
        self.y_test = self.y_train[: n // 2]


@pytest.fixture
def memo_dir(tmp_path):
    _memo.clear()
    _memo.use_folder(str(tmp_path))
    yield tmp_path
    _memo.use_folder(None)
    _memo.clear()


def _tree_equal(a, b):
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb))


def _run(ds, w0, st, effects=(), seed=0):
    return finetune_on(ds, ARCH, w0, s0=0.1, physics=gt.Physics.parse(list(effects), s=st), seed=seed, budget=10,
                       predict_s=st, referee_K2=4)


@pytest.mark.slow
def test_runs_that_differ_only_in_the_chip_share_the_in_silico_work(memo_dir):
    ds, w0 = _DS(), gt.init_params(jax.random.PRNGKey(1), ARCH)
    c0 = _memo.counters()
    a = _run(ds, w0, 0.2)
    c1 = _memo.counters()
    b = _run(ds, w0, 0.05, ("laplace",))
    c2 = _memo.counters()
    for tag in ("direction", "curvature", "pair_se", "slope_s0"):
        assert c1[tag]["misses"] - c0.get(tag, {"misses": 0})["misses"] == 1, tag
        assert c2[tag]["misses"] == c1[tag]["misses"] and c2[tag]["hits"] > c1[tag]["hits"], tag
    # the slope at the chip's level is not shared: a different level is a different entry
    assert c2["slope_st"]["misses"] == c1["slope_st"]["misses"] + 1
    assert _tree_equal(a["direction"], b["direction"])
    assert a["info"]["C2_model"] == b["info"]["C2_model"]
    # a hit returns what a fresh computation returns, bit for bit
    _memo.clear()
    _memo.use_folder(None)
    fresh = _run(ds, w0, 0.05, ("laplace",))
    for k in ("loss_after", "accuracy_after", "test_loss_after"):
        assert fresh[k] == b[k]
    assert _tree_equal(fresh["params"], b["params"])
    assert fresh["info"]["prediction"] == b["info"]["prediction"]


def test_different_inputs_are_different_entries(memo_dir):
    ds = _DS()
    w0 = gt.init_params(jax.random.PRNGKey(1), ARCH)
    w1 = jax.tree_util.tree_map(lambda a: a.at[(0,) * a.ndim].add(1e-6), w0)  # one weight, one ulp-ish
    phys = gt.Physics.create(s=0.2)
    pa = make_problem(ARCH, w0, ds.x_train, ds.y_train, s0=0.1, true_physics=phys, seed=0)
    pb = make_problem(ARCH, w1, ds.x_train, ds.y_train, s0=0.1, true_physics=phys, seed=0)
    pc = make_problem(ARCH, w0, ds.x_train, ds.y_train, s0=0.1, true_physics=phys, seed=1)
    pd = make_problem(ARCH, w0, ds.x_train, ds.y_train, s0=0.15, true_physics=phys, seed=0)
    hits = _memo.counters().get("direction", {"hits": 0})["hits"]
    ua = direction(pa, "pathwise")[0]
    for p in (pb, pc, pd):
        assert not _tree_equal(ua, direction(p, "pathwise")[0])
    assert _memo.counters()["direction"]["hits"] == hits
    assert len(os.listdir(memo_dir)) == 4


@pytest.mark.slow
def test_a_stored_entry_serves_another_process(memo_dir):
    code = ("import jax, numpy as np; from gift_theory import _memo; _memo.use_folder(%r);"
            "v = _memo.memoized('t', (np.arange(3.0), 0.5), lambda: (jax.numpy.arange(4.0) * 0.1, {'n': 1.5}));"
            "print(_memo.counters()['t']['hits'], float(v[0][3]), v[1]['n'])") % str(memo_dir)
    outs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
            for _ in range(2)]
    assert outs[0][0] == "0" and outs[1][0] == "1"
    assert outs[0][1:] == outs[1][1:]


def test_the_referee_scores_a_repeated_set_once_with_the_numbers_of_a_full_pass(memo_dir):
    ds = _DS()
    a, b = gt.init_params(jax.random.PRNGKey(1), ARCH), gt.init_params(jax.random.PRNGKey(2), ARCH)
    phys = gt.Physics.create(s=0.2, shot=0.01)
    from gift_theory._objective import per_input_scores

    full_l, full_c = per_input_scores(jax.random.PRNGKey(12345), [a, b], ds.x_train, ds.y_train, ds.labels_train,
                                      phys, ARCH, 4)
    c0 = _memo.counters().get("referee_first", {"hits": 0, "misses": 0})
    l1, c1 = referee_scores([a, b, a], ds.x_train, ds.y_train, ds.labels_train, phys, ARCH, K2=4)
    assert _memo.counters()["referee_first"]["misses"] == c0["misses"] + 1
    l2, c2 = referee_scores([a, a], ds.x_train, ds.y_train, ds.labels_train, phys, ARCH, K2=4)  # w0 from the memo
    assert _memo.counters()["referee_first"]["hits"] == c0["hits"] + 1
    np.testing.assert_array_equal(l1, np.stack([full_l[0], full_l[1], full_l[0]]))
    np.testing.assert_array_equal(c1, np.stack([full_c[0], full_c[1], full_c[0]]))
    np.testing.assert_array_equal(l2, np.stack([full_l[0], full_l[0]]))
    # another physics is another entry
    referee_scores([a], ds.x_train, ds.y_train, ds.labels_train, gt.Physics.create(s=0.21, shot=0.01), ARCH, K2=4)
    assert _memo.counters()["referee_first"]["misses"] == c0["misses"] + 2
