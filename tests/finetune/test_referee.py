"""The fused referee (weight sets and quantities on one set of draws), the per-input directional
derivative, and Theorem 1's first-order prediction against the realised change.

Private names on purpose: the shared draws across weight sets, the central-difference law of
the directional derivative and the prediction's agreement with the realised change are
numerical contracts that ``run_finetune``'s output only reports, never isolates."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory._objective import directional_derivative, per_input_scores
from gift_theory.finetune import make_problem, referee, referee_losses
from gift_theory.finetune._predict import candidate, first_order_prediction, realised_change
from gift_theory.finetune._problem import referee_scores

from .test_finetune import unit

ARCH = gt.Architecture((6, 5, 4, 3))
Z = 4.0


def _data(n=300, seed=0):
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    x = jax.random.normal(k1, (n, ARCH.widths[0]))
    labels = jax.random.randint(k2, (n,), 0, ARCH.widths[-1])
    return x, jax.nn.one_hot(labels, ARCH.widths[-1]), labels


def _weights(seed):
    return gt.init_params(jax.random.PRNGKey(seed), ARCH)


@pytest.mark.slow
def test_weight_sets_share_draws_and_match_the_single_set_functions():
    x, y, lab = _data()
    a, b = _weights(0), _weights(1)
    phys = gt.Physics.create(s=0.2, shot=0.01)
    key = jax.random.PRNGKey(3)
    losses, correct = per_input_scores(key, [a, b], x, y, lab, phys, ARCH, K2=5, chunk=64)
    assert losses.shape == correct.shape == (2, x.shape[0])
    for i, w in enumerate((a, b)):  # each set alone: the same numbers (same blocks, same draws)
        np.testing.assert_allclose(losses[i], gt.per_input_loss(key, w, x, y, phys, ARCH, K2=5, chunk=64), rtol=1e-5)
        np.testing.assert_allclose(correct[i], gt.accuracy(key, w, x, lab, phys, ARCH, K2=5, chunk=64).samples,
                                   rtol=1e-6)
    assert set(np.unique(correct * 5)) <= set(range(6))  # fractions of the 5 draws
    # the referee's loss draws are those of referee_losses, for every weight set
    rl, rc = referee_scores([a, b], x, y, lab, phys, ARCH, K2=8)
    np.testing.assert_allclose(rl[1], referee_losses(b, x, y, phys, ARCH, K2=8), rtol=1e-5)
    one = referee(b, x, y, lab, phys, ARCH, K2=8)
    assert one["loss"] == pytest.approx(float(rl[1].mean()), rel=1e-6)
    assert one["accuracy"] == pytest.approx(float(rc[1].mean()), rel=1e-6)


def test_without_noise_accuracy_is_the_argmax_of_the_deterministic_output():
    x, y, lab = _data(50)
    w = _weights(2)
    out = gt.forward(w, x, {}, gt.awgn(0.0), ARCH).y
    _, correct = per_input_scores(jax.random.PRNGKey(0), [w], x, None, lab, gt.awgn(0.0), ARCH, K2=3)
    np.testing.assert_array_equal(correct[0], np.asarray(jnp.argmax(out, -1) == lab, float))


@pytest.mark.slow
def test_directional_derivative_is_the_central_difference_on_common_draws(x64):
    x, y, _ = _data(80)
    w = gt.cast_params(_weights(4), jnp.float64)
    u, _ = unit(jax.tree_util.tree_map(lambda a: jax.random.normal(jax.random.PRNGKey(9), a.shape, a.dtype), w))
    phys, key, h = gt.awgn(0.3), jax.random.PRNGKey(5), 1e-4
    est = directional_derivative(key, w, u, x, y, phys, ARCH, K2=4)
    lp = gt.per_input_loss(key, jax.tree_util.tree_map(lambda a, b: a + h * b, w, u), x, y, phys, ARCH, K2=4)
    lm = gt.per_input_loss(key, jax.tree_util.tree_map(lambda a, b: a - h * b, w, u), x, y, phys, ARCH, K2=4)
    np.testing.assert_allclose(est.samples, (lp - lm) / (2 * h), rtol=1e-5, atol=1e-8)
    assert est.n == x.shape[0] and est.se > 0


@pytest.mark.slow
def test_first_order_prediction_agrees_with_the_realised_change_at_a_small_step():
    """The chip's physics is the model's (AWGN at st): at a step where the quadratic term is
    negligible, a <grad J_st, u> predicts the referee's paired change within their errors."""
    x, y, lab = _data(400, seed=1)
    w0 = _weights(5)
    st = 0.15
    problem = make_problem(ARCH, w0, x, y, s0=0.05, true_physics=gt.awgn(st), budget=5)
    u, _ = unit(jax.tree_util.tree_map(lambda a: jax.random.normal(jax.random.PRNGKey(7), a.shape), w0))
    pred = first_order_prediction(problem, u, -0.02, st, curvature=None, K2=32)
    cand, u_unit = candidate(w0, u, -0.02)
    losses, _ = referee_scores([w0, cand], x, y, lab, gt.awgn(st), ARCH, K2=32)
    real = realised_change(losses[0], losses[1])
    assert abs(pred["predicted_change"]) > 5 * pred["predicted_change_se"]  # a measurable change
    z = (real["realised_change"] - pred["predicted_change"]) / np.hypot(real["realised_change_se"],
                                                                       pred["predicted_change_se"])
    assert abs(z) < Z, z
    assert np.isnan(pred["predicted_change_2nd"])  # no curvature given
