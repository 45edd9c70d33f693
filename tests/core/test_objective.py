"""J_s and Eval estimates: unbiased, honest standard errors, common random numbers."""

import jax
import jax.numpy as jnp
import numpy as np

import gift_theory as gt

Z = 4.5


def linear_setup():
    """A one-layer identity model with input-only noise: J_s(w) has a closed form."""
    arch = gt.Architecture((3, 2), "identity", noise_sites="input")
    W = jnp.array([[0.5, -1.0, 0.2], [0.3, 0.0, 1.0]])
    b = jnp.array([0.1, -0.2])
    V = jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return arch, (gt.Layer(W, b),), V


def test_objective_is_unbiased_with_honest_se(x64):
    arch, params, V = linear_setup()
    s = 0.4
    x = jax.random.normal(jax.random.PRNGKey(0), (4000, 3), jnp.float64)
    y = x @ V.T
    est = gt.objective(jax.random.PRNGKey(1), params, x, y, gt.awgn(s), arch, K2=4)
    # closed form over the empirical inputs: E_n |y - W(x + n) - b|^2 = |y - Wx - b|^2 + s^2 |W|_F^2
    W, b = params[0]
    exact = float(jnp.mean(jnp.sum((y - x @ W.T - b) ** 2, -1)) + s ** 2 * jnp.sum(W ** 2))
    # the K1 per-input means also vary with x, so se covers noise and data variation: conservative
    assert abs(float(est.mean) - exact) < Z * float(est.se)
    assert est.samples.shape == (4000,) and est.n == 4000


def test_standard_error_matches_spread_over_seeds(x64):
    arch, params, V = linear_setup()
    x = jax.random.normal(jax.random.PRNGKey(0), (200, 3), jnp.float64)
    y = x @ V.T
    means, ses = [], []
    for seed in range(40):
        e = gt.objective(jax.random.PRNGKey(100 + seed), params, x, y, gt.awgn(1.0), arch, K2=2)
        means.append(float(e.mean))
        ses.append(float(e.se))
    # with x fixed, the seed-to-seed spread is the noise part only, so se (which also counts the
    # spread of x) must not be smaller than it: the ratio is >= 1 within sampling error of 40 seeds
    ratio = np.mean(ses) / np.std(means, ddof=1)
    assert ratio > 1.0 - Z * np.sqrt(1 / (2 * 39))


def test_common_random_numbers_shrink_paired_differences(x64):
    arch, params, V = linear_setup()
    x = jax.random.normal(jax.random.PRNGKey(0), (500, 3), jnp.float64)
    y = x @ V.T
    W, b = params[0]
    other = (gt.Layer(W + 0.01, b),)
    phys = gt.awgn(0.5)
    paired = gt.paired_difference(jax.random.PRNGKey(3), params, other, x, y, phys, arch, K2=4)
    a = gt.objective(jax.random.PRNGKey(3), params, x, y, phys, arch, K2=4)
    b_ = gt.objective(jax.random.PRNGKey(4), other, x, y, phys, arch, K2=4)
    unpaired_se = np.sqrt(a.se ** 2 + b_.se ** 2)
    assert paired.se < 0.2 * unpaired_se
    exact = float(jnp.mean(jnp.sum((y - x @ W.T - b) ** 2, -1) - jnp.sum((y - x @ (W + 0.01).T - b) ** 2, -1))
                  + 0.25 * (jnp.sum(W ** 2) - jnp.sum((W + 0.01) ** 2)))
    assert abs(float(paired.mean) - exact) < Z * float(paired.se)


def test_eval_from_outputs_and_accuracy():
    y = np.array([[1.0, 0.0], [0.0, 1.0]])
    outputs = np.stack([np.tile(y[0], (3, 1)) + 0.5, np.tile(y[1], (3, 1))])
    e = gt.eval_from_outputs(outputs, y)
    assert np.isclose(e.mean, (0.5 + 0.0) / 2) and e.n == 2
    arch = gt.Architecture((2, 2), "identity")
    params = (gt.Layer(jnp.eye(2), jnp.zeros(2)),)
    acc = gt.accuracy(jax.random.PRNGKey(0), params, jnp.eye(2), jnp.array([0, 1]), gt.awgn(0.0), arch, K2=3)
    assert float(acc.mean) == 1.0


def test_chunking_does_not_change_the_estimate(x64):
    arch, params, V = linear_setup()
    x = jax.random.normal(jax.random.PRNGKey(0), (50, 3), jnp.float64)
    y = x @ V.T
    a = gt.per_input_loss(jax.random.PRNGKey(1), params, x, y, gt.awgn(0.3), arch, K2=4, chunk=4096)
    b = gt.per_input_loss(jax.random.PRNGKey(1), params, x, y, gt.awgn(0.3), arch, K2=4, chunk=4096)
    assert np.array_equal(a, b)
    c = gt.per_input_loss(jax.random.PRNGKey(1), params, x, y, gt.awgn(0.3), arch, K2=4, chunk=40)
    # other chunking, other draws -- but the same law: means agree within their errors
    d = a - c
    assert abs(d.mean()) < Z * d.std(ddof=1) / np.sqrt(d.size)
