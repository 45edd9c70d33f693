"""The JAX forward pass against an independent plain-numpy transcription of the paper's
equations (def:matrices-Ai, def:matrix-AL) and of CONTRACTS §2, for fixed noise draws."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import gift_theory as gt
from gift_theory.effects.weight_error import device_draw


def reference(params, x, noise, effects: dict, widths, activation, t=None, seed=0):
    """One input, one shot, written loop by loop from the printed equations."""
    sig = {"tanh": np.tanh, "identity": lambda z: z}[activation]
    s = effects.get("awgn", 0.0)
    L = len(widths) - 1
    a = np.array([x[j] + s * noise["a0"][j] for j in range(widths[0])])
    taps = []
    for l in range(1, L + 1):
        W, b = (np.asarray(p, np.float64) for p in params[l - 1])
        Weff = W.copy()
        if "crosstalk" in effects:
            k = effects["crosstalk"]
            for i in range(W.shape[0]):
                for j in range(W.shape[1]):
                    left = W[i, j - 1] if j - 1 >= 0 else 0.0
                    right = W[i, j + 1] if j + 1 < W.shape[1] else 0.0
                    Weff[i, j] = W[i, j] + k * (left + right)
        if "weight_error" in effects:
            Weff = Weff + effects["weight_error"] * np.asarray(device_draw(seed, l, W.shape, jnp.float64))
        z = np.zeros(widths[l])
        for i in range(widths[l]):
            u = sum(Weff[i, j] * a[j] for j in range(widths[l - 1]))
            g = 1.0
            if "multiplicative" in effects:
                g *= 1 + effects["multiplicative"] * noise[f"mult{l}"][i]
            if "common_mode" in effects:
                g *= 1 + effects["common_mode"] * noise[f"cm{l}"]
            if "drift" in effects and t is not None:
                g *= 1 + effects["drift"] * t
            z[i] = g * u + b[i] + s * noise[f"w{l}"][i]
        a = np.array([sig(z[i]) + s * noise[f"a{l}"][i] for i in range(widths[l])]) if l < L else z.copy()
        if "saturation" in effects:
            a = effects["saturation"] * np.tanh(a / effects["saturation"])
        if "shot" in effects:
            a = a + np.sqrt(effects["shot"] * np.abs(a)) * noise[f"shot{l}"]
        if "quantization" in effects:
            bits, vr = effects["quantization"]
            step = 2 * vr / 2 ** bits
            a = np.clip(np.round(a / step) * step, -vr, vr)
        taps.append(a)
    return a, taps


def _physics(effects):
    kw = {}
    for name, v in effects.items():
        if name == "awgn":
            continue
        kw[name] = dict(bits=v[0], v_range=v[1]) if name == "quantization" else v
    return gt.Physics.create(s=effects.get("awgn", 0.0), **kw)


@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_paper_model_matches_numpy(x64, activation):
    arch = gt.Architecture((5, 4, 3, 2), activation)
    params = gt.init_params(jax.random.PRNGKey(3), arch, dtype=jnp.float64)
    params = tuple(gt.Layer(W, 0.3 * jnp.arange(W.shape[0], dtype=jnp.float64)) for W, _ in params)
    phys = gt.awgn(0.3)
    x = np.asarray(jax.random.normal(jax.random.PRNGKey(4), (6, 5), jnp.float64))
    noise = gt.sample_noise(jax.random.PRNGKey(5), arch, phys, (6,), jnp.float64)
    out = gt.forward(params, jnp.asarray(x), noise, phys, arch, taps=True)
    for n in range(6):
        ref, taps = reference(params, x[n], {k: np.asarray(v[n]) for k, v in noise.items()}, {"awgn": 0.3},
                              arch.widths, activation)
        np.testing.assert_allclose(np.asarray(out.y[n]), ref, rtol=1e-12, atol=1e-12)
        for got, want in zip(out.taps, taps):
            np.testing.assert_allclose(np.asarray(got[n]), want, rtol=1e-12, atol=1e-12)


def test_every_effect_matches_numpy(x64):
    effects = {"awgn": 0.2, "multiplicative": 0.1, "common_mode": 0.05, "drift": 0.3, "crosstalk": 0.1,
               "weight_error": 0.05, "saturation": 1.5, "shot": 0.02, "quantization": (6, 2.0)}
    arch = gt.Architecture((4, 5, 3))
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    phys = _physics(effects)
    x = np.asarray(jax.random.normal(jax.random.PRNGKey(1), (5, 4), jnp.float64))
    t = np.linspace(0, 1, 5)
    noise = gt.sample_noise(jax.random.PRNGKey(2), arch, phys, (5,), jnp.float64)
    out = gt.forward(params, jnp.asarray(x), noise, phys, arch, t=jnp.asarray(t), taps=True)
    for n in range(5):
        ref, taps = reference(params, x[n], {k: np.asarray(v[n]) for k, v in noise.items()}, effects,
                              arch.widths, "tanh", t=t[n])
        for got, want in zip(out.taps, taps):
            # quantization can flip a value that sits on a rounding edge: allow one step there
            step = 2 * 2.0 / 2 ** 6
            np.testing.assert_array_less(np.abs(np.asarray(got[n]) - want), 1e-9 + step * (np.abs(got[n] - want) > 1e-9))
        np.testing.assert_allclose(np.asarray(out.y[n]), ref, atol=step + 1e-9)


@given(widths=st.lists(st.integers(1, 5), min_size=2, max_size=4), seed=st.integers(0, 10_000),
       s=st.floats(0.0, 1.0))
@pytest.mark.slow
def test_random_architectures_match_numpy(widths, seed, s):
    with jax.enable_x64(True):
        arch = gt.Architecture(tuple(widths))
        params = gt.init_params(jax.random.PRNGKey(seed), arch, dtype=jnp.float64)
        phys = gt.awgn(s)
        x = np.asarray(jax.random.normal(jax.random.PRNGKey(seed + 1), (2, widths[0]), jnp.float64))
        noise = gt.sample_noise(jax.random.PRNGKey(seed + 2), arch, phys, (2,), jnp.float64)
        out = gt.forward(params, jnp.asarray(x), noise, phys, arch)
        for n in range(2):
            ref, _ = reference(params, x[n], {k: np.asarray(v[n]) for k, v in noise.items()}, {"awgn": s},
                               arch.widths, "tanh")
            np.testing.assert_allclose(np.asarray(out.y[n]), ref, rtol=1e-12, atol=1e-12)


def test_input_only_noise_placement(x64):
    arch = gt.Architecture((3, 2, 1), "identity", noise_sites="input")
    phys = gt.awgn(0.5)
    noise = gt.sample_noise(jax.random.PRNGKey(0), arch, phys, (4,), jnp.float64)
    assert set(noise) == {"a0"}
    params = gt.init_params(jax.random.PRNGKey(1), arch, dtype=jnp.float64)
    x = jnp.ones((4, 3))
    W = params[1].W @ params[0].W
    want = (x + 0.5 * noise["a0"]) @ W.T + params[1].W @ params[0].b + params[1].b
    np.testing.assert_allclose(gt.forward(params, x, noise, phys, arch).y, want, rtol=1e-12)


def test_hierarchical_broadcast_equals_repeat(x64):
    """x of shape (K1, 1, d0) against draws (K1, K2, .) equals repeating x K2 times."""
    arch = gt.Architecture((3, 4, 2))
    phys = gt.Physics.create(s=0.2, shot=0.01, common_mode=0.1)
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    x = jax.random.normal(jax.random.PRNGKey(1), (5, 3), jnp.float64)
    noise = gt.sample_noise(jax.random.PRNGKey(2), arch, phys, (5, 7), jnp.float64)
    a = gt.forward(params, x[:, None, :], noise, phys, arch).y
    b = gt.forward(params, jnp.repeat(x[:, None, :], 7, axis=1), noise, phys, arch).y
    np.testing.assert_allclose(a, b, rtol=1e-13)


def test_jit_equals_eager_and_float32_close_to_float64():
    arch = gt.Architecture((6, 5, 3))
    phys = gt.Physics.create(s=0.1, multiplicative=0.05, crosstalk=0.1)
    with jax.enable_x64(True):
        p64 = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
        x64_ = jax.random.normal(jax.random.PRNGKey(1), (8, 6), jnp.float64)
        n64 = gt.sample_noise(jax.random.PRNGKey(2), arch, phys, (8,), jnp.float64)
        eager = gt.forward(p64, x64_, n64, phys, arch).y
        jitted = jax.jit(gt.forward, static_argnames=("arch", "taps"))(p64, x64_, n64, phys, arch).y
        np.testing.assert_allclose(eager, jitted, rtol=1e-12)
        eager = np.asarray(eager)
        p32 = jax.tree_util.tree_map(lambda a: np.asarray(a, np.float32), p64)
        n32 = {k: np.asarray(v, np.float32) for k, v in n64.items()}
        x32 = np.asarray(x64_, np.float32)
    y32 = gt.forward(p32, x32, n32, phys, arch).y
    assert y32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(y32), eager, rtol=1e-4, atol=1e-5)


def test_same_seed_same_numbers():
    arch = gt.Architecture((4, 3, 2))
    phys = gt.Physics.create(s=0.1, shot=0.01, weight_error=0.02)
    p = gt.init_params(jax.random.PRNGKey(0), arch)
    x = jnp.ones((3, 4))
    a = gt.simulate(jax.random.PRNGKey(7), p, x, phys, arch, shots=5).y
    b = gt.simulate(jax.random.PRNGKey(7), p, x, phys, arch, shots=5).y
    c = gt.simulate(jax.random.PRNGKey(8), p, x, phys, arch, shots=5).y
    assert np.array_equal(np.asarray(a), np.asarray(b))
    assert not np.array_equal(np.asarray(a), np.asarray(c))


def test_adding_an_effect_keeps_the_additive_draws():
    """Common random numbers across models: the awgn draws do not move when shot noise is added."""
    arch = gt.Architecture((4, 3, 2))
    a = gt.sample_noise(jax.random.PRNGKey(0), arch, gt.awgn(0.1), (5,))
    b = gt.sample_noise(jax.random.PRNGKey(0), arch, gt.Physics.create(s=0.1, shot=0.01), (5,))
    for k in a:
        assert np.array_equal(np.asarray(a[k]), np.asarray(b[k]))


def test_differentiable_in_every_continuous_parameter(x64):
    arch = gt.Architecture((3, 4, 2))
    phys = gt.Physics.create(s=0.2, multiplicative=0.1, common_mode=0.1, crosstalk=0.05, weight_error=0.05,
                             saturation=2.0, shot=0.05, drift=0.1)
    params = gt.init_params(jax.random.PRNGKey(0), arch, dtype=jnp.float64)
    x = jax.random.normal(jax.random.PRNGKey(1), (6, 3), jnp.float64)
    noise = gt.sample_noise(jax.random.PRNGKey(2), arch, phys, (6,), jnp.float64)
    t = jnp.linspace(0.0, 1.0, 6)

    def f(ph):
        return jnp.sum(gt.forward(params, x, noise, ph, arch, t=t).y ** 2)

    f = jax.jit(f)  # one program for the gradient and every finite difference (Physics is a pytree)
    g = jax.grad(f)(phys)
    h = 1e-6
    for e_auto, e in zip(g.effects, phys.effects):
        for p in e.params:
            up = phys.replace(**{p: getattr(e, p) + h})
            dn = phys.replace(**{p: getattr(e, p) - h})
            fd = (f(up) - f(dn)) / (2 * h)
            np.testing.assert_allclose(getattr(e_auto, p), fd, rtol=1e-5, atol=1e-7, err_msg=p)
