"""Each physical effect obeys the law CONTRACTS §2 states for it.

Statistical tolerances are derived from standard errors (4.5 SE: a false failure has
probability below 1e-5 per assertion under a normal approximation)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

import gift_theory as gt
from gift_theory.effects.crosstalk import neighbour_sum

Z = 4.5


def signal_layer(v):
    """A one-layer identity network whose weighted sum for input x = 1 is exactly ``v``."""
    v = jnp.asarray(v, jnp.float64)
    arch = gt.Architecture((1, v.shape[0]), "identity")
    return arch, (gt.Layer(v[:, None], jnp.zeros_like(v)),)


def shots_of(physics, v, R, key=0, t=None):
    arch, params = signal_layer(v)
    out = gt.simulate(jax.random.PRNGKey(key), params, jnp.ones((1, 1)), physics, arch, shots=R, t=t)
    return np.asarray(out.y[0])  # (R, n)


def variance_slope(physics, v, R):
    """Slope of log variance against log |signal|, with its standard error."""
    y = shots_of(physics, v, R)
    logvar = np.log(y.var(axis=0, ddof=1))
    fit = stats.linregress(np.log(np.abs(np.asarray(v))), logvar)
    return fit.slope, fit.stderr, fit.intercept


V = np.geomspace(0.1, 10.0, 12)


def test_shot_variance_linear_in_signal(x64):
    q = 0.02
    slope, se, intercept = variance_slope(gt.Physics.create(s=None, shot=q), V, 4000)
    assert abs(slope - 1.0) < Z * se + 0.01
    assert abs(intercept - np.log(q)) < 0.1  # log var has se ~ sqrt(2/R) = 0.022 per point


def test_multiplicative_variance_quadratic_in_signal(x64):
    slope, se, intercept = variance_slope(gt.Physics.create(s=None, multiplicative=0.1), V, 4000)
    assert abs(slope - 2.0) < Z * se + 0.01
    assert abs(intercept - np.log(0.01)) < 0.1


def test_common_mode_correlates_a_layer_and_nothing_else(x64):
    c, s, R = 0.2, 0.1, 20_000
    arch = gt.Architecture((1, 3, 3), "identity")
    v = jnp.array([0.5, 1.0, 2.0])
    params = (gt.Layer(v[:, None], jnp.zeros(3)), gt.Layer(jnp.eye(3), jnp.zeros(3)))
    phys = gt.Physics.create(s=None, common_mode=c)
    out = gt.simulate(jax.random.PRNGKey(1), params, jnp.ones((2, 1)), phys, arch, shots=R, taps=True)
    a1 = np.asarray(out.taps[0])  # (2, R, 3)
    a2 = np.asarray(out.taps[1])
    # within a layer: every neuron moves with the same gain -> correlation one
    assert np.corrcoef(a1[0].T).min() > 0.999
    # across layers: the layer-2 gain a2/a1 is independent of the layer-1 gain a1/v
    g1 = a1[0, :, 0] / 0.5
    g2 = a2[0, :, 0] / a1[0, :, 0]
    assert abs(np.corrcoef(g1, g2)[0, 1]) < Z / np.sqrt(R)
    # across shots and across inputs: independent
    assert abs(np.corrcoef(g1[:-1], g1[1:])[0, 1]) < Z / np.sqrt(R)
    assert abs(np.corrcoef(a1[0, :, 0], a1[1, :, 0])[0, 1]) < Z / np.sqrt(R)
    # with additive noise as well, the within-layer correlation is the predicted one:
    # z_i = (1 + c xi)(1 + s n_0) v_i + s n_wi, so Cov_ij = v_i v_j ((1 + c^2)(1 + s^2) - 1) (i != j)
    # and Var_i = v_i^2 ((1 + c^2)(1 + s^2) - 1) + s^2
    arch1, params1 = signal_layer(v)
    out = gt.simulate(jax.random.PRNGKey(2), params1, jnp.ones((1, 1)), gt.Physics.create(s=s, common_mode=c),
                      arch1, shots=R)
    z = np.asarray(out.y[0])
    vv = np.asarray(v)
    k = (1 + c ** 2) * (1 + s ** 2) - 1
    for i, j in [(0, 1), (0, 2), (1, 2)]:
        pred = vv[i] * vv[j] * k / np.sqrt((vv[i] ** 2 * k + s ** 2) * (vv[j] ** 2 * k + s ** 2))
        got = np.corrcoef(z[:, i], z[:, j])[0, 1]
        assert abs(np.arctanh(got) - np.arctanh(pred)) < Z / np.sqrt(R - 3)


def batch_kurtosis(x, batches=40):
    xb = x.reshape(batches, -1)
    k = stats.kurtosis(xb, axis=1)  # excess kurtosis per batch
    return k.mean(), k.std(ddof=1) / np.sqrt(batches)


@pytest.mark.parametrize("law,excess", [("laplace", 3.0), ("uniform", -1.2), ("awgn", 0.0)])
def test_noise_laws_keep_s_and_have_their_kurtosis(x64, law, excess):
    s, R = 0.3, 400_000
    arch = gt.Architecture((1, 1), "identity", noise_sites="input")
    phys = gt.awgn(s) if law == "awgn" else gt.Physics.parse([law], s=s)
    params = (gt.Layer(jnp.ones((1, 1)), jnp.zeros(1)),)
    out = gt.simulate(jax.random.PRNGKey(3), params, jnp.zeros((1, 1)), phys, arch, shots=R)
    n = np.asarray(out.y).ravel()
    # standard deviation: se of the sample sd is about sd * sqrt((kurt + 2) / (4 n))
    sd_se = s * np.sqrt((excess + 2) / (4 * R))
    assert abs(n.std() - s) < Z * sd_se
    k, k_se = batch_kurtosis(n)
    assert abs(k - excess) < Z * k_se


@given(bits=st.integers(1, 12), v_range=st.floats(0.05, 10.0), scale=st.floats(0.01, 50.0))
def test_quantization_lands_on_the_lattice(bits, v_range, scale):
    with jax.enable_x64(True):
        v = scale * np.linspace(-1.5, 1.5, 31)
        y = shots_of(gt.Physics.create(s=None, quantization=dict(bits=bits, v_range=v_range)), v, 1)[0]
        step = 2 * v_range / 2 ** bits
        k = y / step
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
        assert np.all(np.abs(y) <= v_range * (1 + 1e-12))


def test_quantization_has_the_derivative_of_its_expected_readout(x64):
    """The rounding's own derivative is 0 a.e.: a quantized model had no gradient at all, so
    training under it returned its start. The derivative used is that of the expected readout
    E[round((v + n) / h) h] under the awgn n before D, which is 1 when h <= sd(n): checked
    against a central difference (over +-5 steps, common random numbers) of the mean of R
    shots, within Z of its standard error."""
    h, s, R = 0.01, 0.01, 40_000
    phys = gt.Physics.create(s=s, quantization=dict(bits=8, v_range=h * 2 ** 7))
    v = jnp.array([0.123, -0.4567, 0.0031])
    arch, params = signal_layer(v)
    noise = gt.sample_noise(jax.random.PRNGKey(3), arch, phys, (1, R), jnp.float64)

    def per_shot(u):  # (R, 3): the readout of each shot with the weighted sum u
        return gt.forward((gt.Layer(u[:, None], params[0].b),), jnp.ones((1, 1, 1)), noise, phys, arch).y[0]

    J = np.einsum("rii->ri", np.asarray(jax.jacfwd(per_shot)(v)))  # (R, 3) each shot's own derivative
    plain = gt.Physics.create(s=s)  # the same draws without D: the derivative is 1 + s n_a0 per shot
    J_plain = np.einsum("rii->ri", np.asarray(jax.jacfwd(
        lambda u: gt.forward((gt.Layer(u[:, None], params[0].b),), jnp.ones((1, 1, 1)), noise, plain, arch).y[0])(v)))
    np.testing.assert_allclose(J, J_plain, rtol=1e-12)
    d = 5 * h
    diff = (np.asarray(per_shot(v + d)) - np.asarray(per_shot(v - d))) / (2 * d) - J  # paired per shot
    bias, se = diff.mean(0), diff.std(0, ddof=1) / np.sqrt(R)
    assert np.all(se > 0)
    assert np.all(np.abs(bias) <= Z * se + 1e-8), (bias, se)


def test_training_under_quantization_moves_the_weights_as_without_it(x64):
    """At 16 bits the quantized loss is the unquantized one up to the step: so is its gradient
    (the same draws). Before the straight-through derivative it was exactly zero."""
    arch = gt.Architecture((4, 6, 3), "tanh")
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    x = jax.random.normal(jax.random.PRNGKey(1), (32, 4), jnp.float64)
    y = jax.random.normal(jax.random.PRNGKey(2), (32, 3), jnp.float64)
    plain = gt.Physics.create(s=0.05)
    quant = gt.Physics.create(s=0.05, quantization=dict(bits=16, v_range=8.0))
    noise = gt.sample_noise(jax.random.PRNGKey(4), arch, quant, (32, 8), jnp.float64)

    def loss(p, phys):
        return jnp.mean(gt.squared_error(gt.forward(p, x[:, None, :], noise, phys, arch).y, y[:, None, :]))

    gq = jax.tree_util.tree_leaves(jax.grad(loss)(params, quant))
    gp = jax.tree_util.tree_leaves(jax.grad(loss)(params, plain))
    scale = max(float(jnp.max(jnp.abs(a))) for a in gp)
    assert scale > 1e-3
    for a, b in zip(gq, gp):
        np.testing.assert_allclose(a, b, atol=1e-3 * scale)


@given(v_max=st.floats(0.01, 100.0), scale=st.floats(0.001, 1e6))
def test_saturation_never_exceeds_v_max(v_max, scale):
    with jax.enable_x64(True):
        v = scale * np.linspace(-1.0, 1.0, 21)
        y = shots_of(gt.Physics.create(s=None, saturation=v_max), v, 1)[0]
        assert np.all(np.abs(y) <= v_max)
        # monotone and odd
        assert np.all(np.diff(y) >= 0)
        np.testing.assert_allclose(y, -y[::-1], atol=1e-12 * max(1.0, v_max))


def test_drift_is_linear_in_time(x64):
    r = 0.3
    v = np.array([0.5, -1.0, 2.0])
    t = jnp.linspace(0.0, 1.0, 50)[None, :]
    y = shots_of(gt.Physics.create(s=None, drift=r), v, 50, t=t)
    for i in range(3):
        fit = stats.linregress(np.asarray(t[0]), y[:, i])
        np.testing.assert_allclose(fit.slope, r * v[i], rtol=1e-9)
        np.testing.assert_allclose(fit.intercept, v[i], rtol=1e-9)
        assert fit.rvalue ** 2 > 1 - 1e-12


@given(rows=st.integers(1, 6), cols=st.integers(1, 7), k=st.floats(-0.5, 0.5), seed=st.integers(0, 999))
def test_crosstalk_matches_the_stated_matrix(rows, cols, k, seed):
    W = np.random.default_rng(seed).normal(size=(rows, cols))
    got = np.asarray(gt.make_effect("crosstalk", k=k).weights(jnp.asarray(W), 1))
    want = W.copy()
    for i in range(rows):
        for j in range(cols):
            want[i, j] = W[i, j] + k * ((W[i, j - 1] if j > 0 else 0) + (W[i, j + 1] if j < cols - 1 else 0))
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    assert neighbour_sum(jnp.ones((1, 1))).shape == (1, 1)


def test_weight_error_fixed_per_device_fresh_across_devices(x64):
    W = jnp.zeros((200, 300))
    e = 0.05
    dev = gt.make_effect("weight_error", e=e, seed=11)
    a, b = dev.weights(W, 1), dev.weights(W, 1)
    assert np.array_equal(np.asarray(a), np.asarray(b))  # same device, same error, every shot
    other = gt.make_effect("weight_error", e=e, seed=12).weights(W, 1)
    assert abs(np.corrcoef(np.asarray(a).ravel(), np.asarray(other).ravel())[0, 1]) < Z / np.sqrt(W.size)
    assert not np.array_equal(np.asarray(dev.weights(W, 2)), np.asarray(a))  # each layer its own E
    sd = float(np.std(np.asarray(a)))
    assert abs(sd - e) < Z * e / np.sqrt(2 * W.size)
    # and the simulated shots see the same E: with no other noise, repeated shots are identical
    arch, params = signal_layer(np.ones(4))
    y = shots_of(gt.Physics.create(s=None, weight_error=dict(e=0.1, seed=3)), np.ones(4), 5)
    assert np.ptp(y, axis=0).max() == 0 and np.abs(y[0] - 1).max() > 0


def test_gains_multiply(x64):
    v = np.array([1.0, 2.0])
    t = jnp.full((1, 3), 0.5)
    y_mult = shots_of(gt.Physics.create(s=None, multiplicative=0.1, drift=0.2), v, 3, key=5, t=t)
    y_one = shots_of(gt.Physics.create(s=None, multiplicative=0.1), v, 3, key=5, t=t)
    np.testing.assert_allclose(y_mult, y_one * (1 + 0.2 * 0.5), rtol=1e-12)


def test_one_compiled_pass_never_serves_another_law(x64):
    """Regression: JAX's treedefs of the parameterless laplace and uniform effects compare
    equal, so a jitted pass compiled for one law was (in some processes) reused for the other."""
    trees = {law: jax.tree_util.tree_structure(gt.Physics.parse([law], s=1.0)) for law in ("laplace", "uniform")}
    assert trees["laplace"] != trees["uniform"]
    arch = gt.Architecture((1, 1), "identity", noise_sites="input")
    params = (gt.Layer(jnp.ones((1, 1)), jnp.zeros(1)),)
    got = {}
    for law in ("laplace", "uniform", "laplace"):
        out = gt.simulate(jax.random.PRNGKey(3), params, jnp.zeros((1, 1)), gt.Physics.parse([law], s=1.0), arch,
                          shots=40_000)
        got.setdefault(law, []).append(stats.kurtosis(np.asarray(out.y).ravel()))
    # excess kurtosis 3 (laplace) against -1.2 (uniform): se ~ sqrt(24 / n) * ... << 1
    assert min(got["laplace"]) > 2.0 and got["uniform"][0] < -1.0
