"""Algorithm 1: the printed selection excludes w0; the corrected one keeps it."""

import jax.numpy as jnp
import numpy as np

import gift_theory as gt
from proofs_checks import algorithm1


def _params(w):
    return (gt.Layer(jnp.asarray([[w]]), jnp.zeros((1,))),)


def _eval(w):
    # a deterministic 'chip': per-input losses (w - 1)^2 + input offsets, minimum at w = 1
    return np.full(32, (float(w[0].W[0, 0]) - 1.0) ** 2) + np.linspace(0, 1e-3, 32)


def test_printed_selection_returns_a_worse_point_at_the_optimum():
    w, info = algorithm1(_eval, _params(1.0), np.array([1.0, 0.0]), 0.1)
    assert info["chosen"] != (0, 0) and _eval(w).mean() > _eval(_params(1.0)).mean()


def test_corrected_selection_keeps_w0_and_improves_elsewhere():
    w, info = algorithm1(_eval, _params(1.0), np.array([1.0, 0.0]), 0.1, keep_w0=True, delta=0.05)
    assert info["chosen"] == (0, 0)
    w, info = algorithm1(_eval, _params(0.0), np.array([1.0, 0.0]), 0.3, keep_w0=True, delta=0.05)
    assert _eval(w).mean() < _eval(_params(0.0)).mean()


def test_eval_decisions_lists_the_comparisons_the_search_made():
    from proofs_checks._gift import eval_decisions

    w0 = _params(0.0)
    w, info = algorithm1(_eval, w0, np.array([1.0, 0.0]), 0.3)       # minimum at w = 1: steps 0.3, 0.6, ...
    dec = eval_decisions(info, w0)
    stops = [d for d in dec if d[0].startswith("stop")]
    selects = [d for d in dec if d[0].startswith("select")]
    assert len(stops) == info["iterations"] and len(selects) == 2 * info["iterations"] - 1
    for label, wa, wb, la, lb in stops[:-1]:          # the search went on: the worse side was still below L0
        assert np.mean(la) < np.mean(lb) and wb is w0
    assert np.mean(stops[-1][3]) >= np.mean(stops[-1][4])
    assert all(np.mean(la) >= np.mean(lb) for _, _, _, la, lb in selects)     # the chosen point is the argmin
