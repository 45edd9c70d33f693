"""``layer_gain`` (CONTRACTS §2: one fixed gain per layer, W_l^eff = g_l W_l, gains multiply)
against a plain-numpy transcription of the contract's equations, for fixed noise draws."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.effects.weight_error import device_draw


def _reference(params, x, noise, g, s, k, e, m, t, seed=0):
    """One input, one shot, loop by loop: crosstalk and weight_error make W_eff, the layer's gain
    g_l multiplies that whole map, the multiplicative and drift gains multiply on top."""
    L = len(params)
    a = np.array([x[j] + s * noise["a0"][j] for j in range(len(x))])
    taps = []
    for l in range(1, L + 1):
        W, b = (np.asarray(p, np.float64) for p in params[l - 1])
        d_out, d_in = W.shape
        Weff = np.zeros_like(W)
        E = np.asarray(device_draw(seed, l, W.shape, jnp.float64))
        for i in range(d_out):
            for j in range(d_in):
                left = W[i, j - 1] if j >= 1 else 0.0
                right = W[i, j + 1] if j + 1 < d_in else 0.0
                Weff[i, j] = g[l - 1] * (W[i, j] + k * (left + right) + e * E[i, j])
        z = np.zeros(d_out)
        for i in range(d_out):
            u = sum(Weff[i, j] * a[j] for j in range(d_in))
            gain = (1 + m * noise[f"mult{l}"][i]) * (1 + 0.3 * t)
            z[i] = gain * u + b[i] + s * noise[f"w{l}"][i]
        a = np.array([np.tanh(z[i]) + s * noise[f"a{l}"][i] for i in range(d_out)]) if l < L else z.copy()
        taps.append(a)
    return a, taps


@pytest.mark.parametrize("g", [(0.6, 0.8, 1.3), (0.45, 0.45, 0.45)])
def test_layer_gain_matches_numpy(x64, g):
    arch = gt.Architecture((4, 5, 3, 2))
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    value = tuple((v,) for v in g) if len(set(g)) > 1 else g[0]  # per layer, or one number for every layer
    phys = gt.Physics.create(s=0.2, layer_gain=dict(g=value), crosstalk=0.1, weight_error=0.05,
                             multiplicative=0.1, drift=0.3)
    x = np.asarray(jax.random.normal(jax.random.PRNGKey(1), (5, 4), jnp.float64))
    t = np.linspace(0, 1, 5)
    noise = gt.sample_noise(jax.random.PRNGKey(2), arch, phys, (5,), jnp.float64)
    out = gt.forward(params, jnp.asarray(x), noise, phys, arch, t=jnp.asarray(t), taps=True)
    for n in range(5):
        ref, taps = _reference(params, x[n], {k: np.asarray(v[n]) for k, v in noise.items()}, g, 0.2, 0.1, 0.05,
                               0.1, t[n])
        for got, want in zip(out.taps, taps):
            np.testing.assert_allclose(np.asarray(got[n]), want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(out.y[n]), ref, rtol=1e-12, atol=1e-12)


def test_layer_gain_at_one_is_the_paper_model(x64):
    arch = gt.Architecture((3, 4, 2))
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    x = jnp.asarray(np.random.default_rng(0).normal(size=(6, 3)))
    base = gt.Physics.create(s=0.1)
    noise = gt.sample_noise(jax.random.PRNGKey(2), arch, base, (6,), jnp.float64)
    a = gt.forward(params, x, noise, base, arch).y
    b = gt.forward(params, x, noise, gt.Physics.create(s=0.1, layer_gain=1.0), arch).y
    assert np.array_equal(np.asarray(a), np.asarray(b))


def test_layer_gain_parses_and_validates_per_layer_values():
    e = gt.effects.parse_effect("layer_gain=0.6")
    assert float(e.g) == 0.6 and e.mechanism == "gain_error" and e.shape == {"g": "layers"}
    arch = gt.Architecture((3, 4, 2))
    phys = gt.Physics.create(s=0.1, layer_gain=dict(g=((0.5,), (2.0,))))
    phys.validate(arch=arch)
    assert phys.params_json()["g"] == [[0.5], [2.0]]
    with pytest.raises(gt.GiftInputError, match="layer 2: 3 values for 1 value"):
        gt.Physics.create(s=0.1, layer_gain=dict(g=((0.5,), (2.0, 1.0, 1.0)))).validate(arch=arch)
    with pytest.raises(gt.GiftInputError, match="outside"):
        gt.make_effect("layer_gain", g=-1.0)
