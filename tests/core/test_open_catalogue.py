"""The open effect catalogue (CONTRACTS §2b, §6): the public plugin API, layer scopes, the
bias and activation stages, per-neuron parameters, the plugin loaders and their errors, and
the built-in effects bias_offset and activation_gain against plain-numpy transcriptions.

Statistical tolerances are 4.5 standard errors (a false failure below 1e-5 per assertion)."""

import importlib.metadata
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory import effects as fx
# private: its record of loaded entry points, emptied so a test starts as a fresh process
from gift_theory.effects import _plugins
from gift_theory.effects import bias_offset, weight_error

Z = 4.5

#: CONTRACTS §2b's example, verbatim
ACT_GAIN = '''\
from gift_theory.effects import Effect, register

@register
class ActGain(Effect):
    kappa: float = 1.0                       # each physical parameter is a dataclass field
    name = "act_gain"
    params = ("kappa",)
    bounds = {"kappa": (0.2, 5.0)}           # fitting searches inside; no private grid table
    defaults = {"kappa": 1.0}
    stage = "activation"
    layers = "hidden"                        # "all" (default) | "hidden" | "output" | (1, 3, ...)
    mechanism = "activation_mismatch"        # one class of §6
    description = "the chip's nonlinearity is sigma(kappa z)"

    def activation(self, z, sigma, layer):   # a_l = D(activation(z_l) + n_al)
        return sigma(self.kappa * z)
'''


@pytest.fixture(autouse=True)
def clean_registry():
    """Every test leaves the registry as it found it (plugins registered here are removed)."""
    before = dict(fx.REGISTRY)
    yield
    fx.REGISTRY.clear()
    fx.REGISTRY.update(before)


def net(widths=(3, 4, 5, 2), seed=0, activation="tanh"):
    arch = gt.Architecture(widths, activation)
    params = gt.init_params(jax.random.PRNGKey(seed), arch, dtype=jnp.float64)
    params = tuple(gt.Layer(W, 0.1 * jnp.arange(W.shape[0], dtype=jnp.float64) - 0.2) for W, _ in params)
    x = np.asarray(jax.random.normal(jax.random.PRNGKey(seed + 1), (6, widths[0]), jnp.float64))
    return arch, params, x


def np_forward(params, x, depth, act=np.tanh, weights=None, bias=None, gain=None, activation=None, readout=None):
    """The noiseless generative process of CONTRACTS §2/§2b in plain numpy; each hook is
    ``f(value, layer)`` (or None) and is the caller's transcription of an effect."""
    a = np.asarray(x, np.float64)
    outs = []
    for l, (W, b) in enumerate(params, start=1):
        W, b = np.asarray(W), np.asarray(b)
        W = weights(W, l) if weights else W
        b = bias(b, l) if bias else b
        u = a @ W.T
        z = (gain(u, l) if gain else 1.0) * u + b
        if l < depth:
            v = activation(z, l) if activation else act(z)
        else:
            v = z
        a = readout(v, l) if readout else v
        outs.append(a)
    return a, outs


def write(tmp_path, text, name="my_effect.py"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


# ---- the public API ----------------------------------------------------------------------

def test_public_api_and_mechanisms():
    assert fx.MECHANISMS == ("noise_level", "noise_law", "input_dependent_noise", "gain_fluctuation",
                             "time_drift", "correlated_noise", "gain_error", "weight_error", "bias_offset",
                             "activation_mismatch", "readout_nonlinearity", "memory")
    assert fx.STAGES == ("level", "law", "weights", "bias", "gain", "activation", "readout")
    assert gt.EFFECT_NAMES == fx.EFFECT_NAMES and len(fx.EFFECT_NAMES) == 11
    assert fx.BUILTIN == fx.EFFECT_NAMES + ("bias_offset", "activation_gain", "layer_gain", "memory")
    assert set(fx.BUILTIN) == set(fx.REGISTRY)
    table6 = {"awgn": "noise_level", "laplace": "noise_law", "uniform": "noise_law",
              "shot": "input_dependent_noise", "multiplicative": "input_dependent_noise",
              "common_mode": "gain_fluctuation", "drift": "time_drift", "crosstalk": "weight_error",
              "weight_error": "weight_error", "saturation": "readout_nonlinearity",
              "quantization": "readout_nonlinearity", "bias_offset": "bias_offset",
              "activation_gain": "activation_mismatch", "layer_gain": "gain_error", "memory": "memory"}
    assert {n: fx.REGISTRY[n].mechanism for n in fx.BUILTIN} == table6
    for n in fx.BUILTIN:
        cls = fx.REGISTRY[n]
        assert cls.layers in ("all", "hidden") and cls.description
        assert cls.shape == ({"g": "layers"} if n == "layer_gain" else {})
        assert fx.register(cls) is cls  # registering the same class again is harmless


def test_acts_on():
    e = gt.make_effect("activation_gain", kappa=2.0)
    assert [e.acts_on(l, 3) for l in (1, 2, 3)] == [True, True, False]
    with pytest.raises(ValueError, match="depth"):
        e.acts_on(1)
    assert gt.make_effect("shot", q=0.1).acts_on(7)


# ---- the two new built-in effects against numpy ------------------------------------------------

@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_activation_gain_matches_numpy(x64, activation):
    arch, params, x = net(activation=activation)
    kappa = 1.7
    phys = gt.Physics.create(s=None, activation_gain=kappa)
    got = gt.forward(params, jnp.asarray(x), {}, phys, arch, taps=True)
    sig = {"tanh": np.tanh, "identity": lambda z: z}[activation]
    want, outs = np_forward(params, x, arch.depth, activation=lambda z, l: sig(kappa * z))
    np.testing.assert_allclose(np.asarray(got.y), want, rtol=1e-12, atol=1e-12)
    for g, w in zip(got.taps, outs):
        np.testing.assert_allclose(np.asarray(g), w, rtol=1e-12, atol=1e-12)
    # kappa = 1 is the paper's model
    base = gt.forward(params, jnp.asarray(x), {}, gt.Physics.create(s=None), arch).y
    one = gt.forward(params, jnp.asarray(x), {}, gt.Physics.create(s=None, activation_gain=1.0), arch).y
    np.testing.assert_array_equal(np.asarray(base), np.asarray(one))
    with pytest.raises(gt.GiftInputError, match="outside"):
        gt.make_effect("activation_gain", kappa=0.01)


def test_bias_offset_matches_numpy(x64):
    arch, params, x = net()
    sigma, seed = 0.3, 5
    phys = gt.Physics.create(s=None, bias_offset=dict(sigma=sigma, seed=seed))
    deltas = [sigma * np.asarray(bias_offset.device_draw(seed, l, (arch.widths[l],), jnp.float64))
              for l in range(1, arch.depth + 1)]
    got = gt.forward(params, jnp.asarray(x), {}, phys, arch, taps=True)
    want, outs = np_forward(params, x, arch.depth, bias=lambda b, l: b + deltas[l - 1])
    np.testing.assert_allclose(np.asarray(got.y), want, rtol=1e-12, atol=1e-12)
    for g, w in zip(got.taps, outs):
        np.testing.assert_allclose(np.asarray(g), w, rtol=1e-12, atol=1e-12)


def test_bias_offset_fixed_per_device_and_normal(x64):
    sigma, n = 0.05, 20_000
    b = jnp.zeros(n)
    dev = gt.make_effect("bias_offset", sigma=sigma, seed=11)
    d1 = np.asarray(dev.bias(b, 1))
    assert np.array_equal(d1, np.asarray(dev.bias(b, 1)))                     # fixed: same device, every call
    assert np.array_equal(d1, np.asarray(gt.make_effect("bias_offset", sigma=sigma, seed=11).bias(b, 1)))
    other = np.asarray(gt.make_effect("bias_offset", sigma=sigma, seed=12).bias(b, 1))
    layer2 = np.asarray(dev.bias(b, 2))
    werr = np.asarray(weight_error.device_draw(11, 1, (n,), jnp.float64))  # weight_error's stream, same seed
    for o in (other, layer2, werr):
        assert abs(np.corrcoef(d1, o)[0, 1]) < Z / np.sqrt(n)
    # N(0, sigma^2): mean, standard deviation, and the whole law (KS)
    assert abs(d1.mean()) < Z * sigma / np.sqrt(n)
    assert abs(d1.std() - sigma) < Z * sigma / np.sqrt(2 * n)
    from scipy import stats
    assert stats.kstest(d1 / sigma, "norm").pvalue > 1e-5
    # repeated shots of one device see the same offsets: without noise every shot is equal
    arch, params, x = net((2, 3, 2))
    phys = gt.Physics.create(s=None, bias_offset=dict(sigma=0.2, seed=3))
    y = np.asarray(gt.simulate(jax.random.PRNGKey(0), params, x, phys, arch, shots=4).y)
    assert np.ptp(y, axis=1).max() == 0
    assert np.abs(y[:, 0] - np.asarray(gt.forward(params, x, {}, gt.Physics.create(s=None), arch).y)).max() > 0


# ---- a plugin in a file --------------------------------------------------------------------------

def test_contract_example_plugin_loads_and_acts(tmp_path, x64):
    path = write(tmp_path, ACT_GAIN)
    assert fx.load_plugin(path) == ["act_gain"]
    assert fx.load_plugin(str(path)) == ["act_gain"]  # loading again is harmless
    cls = fx.REGISTRY["act_gain"]
    assert cls.mechanism == "activation_mismatch" and cls.layers == "hidden"
    arch, params, x = net()
    phys = gt.Physics.parse(["act_gain=0.6"])
    assert phys.names == ("act_gain",) and gt.Physics.create(s=0.1, act_gain=0.6).params() == {"s": 0.1, "kappa": 0.6}
    got = gt.forward(params, jnp.asarray(x), {}, phys, arch, taps=True)
    want, outs = np_forward(params, x, arch.depth, activation=lambda z, l: np.tanh(0.6 * z))
    np.testing.assert_allclose(np.asarray(got.y), want, rtol=1e-12, atol=1e-12)
    # and through the jitted simulator, with noise: the plugin is a pytree like any effect
    y = gt.simulate(jax.random.PRNGKey(0), params, x, gt.Physics.create(s=0.1, act_gain=0.6), arch, shots=3).y
    assert y.shape == (6, 3, 2) and np.isfinite(np.asarray(y)).all()
    with pytest.raises(gt.GiftInputError, match="outside"):
        gt.parse_effect("act_gain=9")


def test_activation_hooks_compose(x64):
    @fx.register
    class Lift(fx.Effect):
        c: float = 0.1
        name = "test_lift"
        params = ("c",)
        stage = "activation"
        order = 5
        mechanism = "activation_mismatch"

        def activation(self, z, sigma, layer):
            return sigma(z) + self.c

    arch, params, x = net()
    phys = gt.Physics.create(s=None, test_lift=0.2, activation_gain=1.5)
    got = gt.forward(params, jnp.asarray(x), {}, phys, arch).y
    # canonical order: activation_gain (order 0) wraps tanh, test_lift (order 5) wraps that
    want, _ = np_forward(params, x, arch.depth, activation=lambda z, l: np.tanh(1.5 * z) + 0.2)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-12)


HOOKS = {
    "weights": ("def weights(self, W, layer):\n    return W * (1 + self.c)", dict(weights=lambda W, c: W * (1 + c))),
    "bias": ("def bias(self, b, layer):\n    return b + self.c", dict(bias=lambda b, c: b + c)),
    "gain": ("def gain(self, noise, layer, t, shape):\n    return 1 + self.c", dict(gain=lambda u, c: 1 + c)),
    "activation": ("def activation(self, z, sigma, layer):\n    return sigma(z) - self.c",
                   dict(activation=lambda z, c: np.tanh(z) - c)),
    "readout": ("def readout(self, v, noise, layer):\n    return v + self.c", dict(readout=lambda v, c: v + c)),
}


TIME_HOOKS = {
    "weights": ("def weights(self, W, layer, t):\n    return W * (1 + self.c * t)",
                dict(weights=lambda W, c, t: W * (1 + c * t))),
    "bias": ("def bias(self, b, layer, t):\n    return b + self.c * t", dict(bias=lambda b, c, t: b + c * t)),
    "activation": ("def activation(self, z, sigma, layer, t):\n    return sigma(z) * (1 - self.c * t)",
                   dict(activation=lambda z, c, t: np.tanh(z) * (1 - c * t))),
    "readout": ("def readout(self, v, noise, layer, t):\n    return v + self.c * t", dict(readout=lambda v, c, t: v + c * t)),
}


@pytest.mark.parametrize("stage", list(TIME_HOOKS))
def test_hooks_take_the_acquisition_time(stage, x64):
    """CONTRACTS §2b (2026-11-25): a hook with a keyword t gets each shot's time, shaped to
    broadcast against its first argument; the forward pass over (inputs, shots) equals the
    noiseless numpy process run shot by shot at that shot's t. Without times t = 0."""
    ns = {}
    src = textwrap.dedent(f"""
        from gift_theory.effects import Effect, register
        class Timed(Effect):
            c: float = 0.0
            name = "test_timed"
            params = ("c",)
            stage = {stage!r}
            mechanism = "time_drift" if "time_drift" in __import__("gift_theory").effects.MECHANISMS else "weight_error"
        """) + textwrap.indent(TIME_HOOKS[stage][0], "    ") + "\n"
    exec(src, ns)
    cls = fx.register(ns["Timed"])
    assert cls.needs_times  # t without a default
    arch, params, x = net((3, 4, 5, 2))
    c, n, r = 0.7, x.shape[0], 3
    t = np.linspace(0.0, 1.0, n * r).reshape(n, r)
    phys = gt.Physics.create(s=None, test_timed=c)
    got = gt.forward(params, jnp.asarray(x)[:, None, :], {}, phys, arch, t=jnp.asarray(t), taps=True)
    (kw, fn), = TIME_HOOKS[stage][1].items()
    for i in range(n):
        for k in range(r):
            hook = (lambda v, l, tt=t[i, k]: fn(v, c, tt)) if kw != "activation" else \
                (lambda z, l, tt=t[i, k]: fn(z, c, tt) if l < arch.depth else z)
            _, outs = np_forward(params, x[i:i + 1], arch.depth, **{kw: hook})
            for g, w in zip(got.taps, outs):
                np.testing.assert_allclose(np.asarray(g)[i, k], w[0], rtol=1e-12, atol=1e-12)
    # without times the hook sees t = 0: the programmed process
    plain = gt.forward(params, jnp.asarray(x), {}, phys, arch).y
    want, _ = np_forward(params, x, arch.depth)
    np.testing.assert_allclose(np.asarray(plain), want, rtol=1e-12, atol=1e-12)


def test_time_keyword_with_default_is_optional(x64):
    @fx.register
    class Opt(fx.Effect):
        c: float = 0.0
        name = "test_opt_time"
        params = ("c",)
        stage = "bias"
        mechanism = "bias_offset"

        def bias(self, b, layer, t=None):
            return b if t is None else b + self.c * t

    assert not Opt.needs_times
    arch, params, x = net()
    phys = gt.Physics.create(s=None, test_opt_time=0.5)
    want, _ = np_forward(params, x, arch.depth)
    np.testing.assert_allclose(np.asarray(gt.forward(params, jnp.asarray(x), {}, phys, arch).y), want, rtol=1e-12)


def test_per_neuron_recipe_and_value_in_hooks(x64):
    """The docs' recipe ``self.alive * sigma(z)`` and ``self.value("alive", layer)`` agree: a hook
    runs on the layer's view of the effect (Effect.at_layer)."""
    outs = {}
    for body in ("self.alive * sigma(z)", 'self.value("alive", layer) * sigma(z)'):
        ns = {}
        exec(textwrap.dedent(f"""
            from gift_theory.effects import Effect, register
            class Alive(Effect):
                alive: float = 1.0
                name = "test_alive"
                params = ("alive",)
                shape = {{"alive": "neurons"}}
                bounds = {{"alive": (0.0, 2.0)}}
                stage = "activation"
                layers = "hidden"
                mechanism = "activation_mismatch"
                def activation(self, z, sigma, layer):
                    return {body}
            """), ns)
        fx.REGISTRY.pop("test_alive", None)
        fx.register(ns["Alive"])
        arch, params, x = net((3, 4, 5, 2))
        alive = (np.array([1.0, 0.0, 0.5, 1.0]), np.linspace(0.2, 1.0, 5), np.ones(2))
        phys = gt.Physics.create(s=None, test_alive={"alive": alive})
        outs[body] = np.asarray(gt.forward(params, jnp.asarray(x), {}, phys, arch).y)
        want, _ = np_forward(params, x, arch.depth, activation=lambda z, l: alive[l - 1] * np.tanh(z))
        np.testing.assert_allclose(outs[body], want, rtol=1e-12, atol=1e-12)
    eff = fx.make_effect("test_alive", alive=alive)
    with pytest.raises(gt.GiftInputError, match="no parameter 'dead'"):
        eff.value("dead", 1)


def test_a_noise_law_may_be_restricted_to_layers():
    # private: which sites a law reaches, which the draws show only statistically
    from gift_theory._model import site_laws

    @fx.register
    class LawTwo(fx.Effect):
        name = "test_law_two"
        stage = "law"
        layers = (2,)
        mechanism = "noise_law"

        @staticmethod
        def standard(key, shape, dtype):
            return jax.random.laplace(key, shape, dtype) / np.sqrt(2.0)

    arch = gt.Architecture((3, 4, 5, 2))
    laws = site_laws(arch, gt.Physics.create(s=0.1, test_law_two=True))
    assert {k for k, (_, law) in laws.items() if law is not None} == {"w2", "a2"}
    laws = site_laws(arch, gt.Physics.create(s=0.1, laplace=True))
    assert {k for k, (_, law) in laws.items() if law is not None} == {"a0", "w1", "a1", "w2", "a2", "w3"}


@pytest.mark.parametrize("stage,layers", [(st, sc) for st in HOOKS for sc in ("all", "hidden", "output", (1, 3), (2,))
                                          if (st, sc) != ("activation", "output")])  # refused (see BAD)
def test_layer_scope_of_every_stage(stage, layers, x64):
    ns = {}
    src = textwrap.dedent(f"""
        from gift_theory.effects import Effect, register
        class Scoped(Effect):
            c: float = 0.0
            name = "test_scoped"
            params = ("c",)
            stage = {stage!r}
            layers = {layers!r}
            mechanism = "weight_error"
        """) + textwrap.indent(HOOKS[stage][0], "    ") + "\n"
    exec(src, ns)
    fx.register(ns["Scoped"])
    arch, params, x = net((3, 4, 5, 2))  # L = 3
    c = 0.3
    inside = {"all": (1, 2, 3), "hidden": (1, 2), "output": (3,)}.get(layers, layers)
    if stage == "activation":
        inside = tuple(l for l in inside if l < arch.depth)
    (kw, fn), = HOOKS[stage][1].items()
    hook = lambda v, l: fn(v, c) if l in inside else (np.tanh(v) if kw == "activation" else
                                                       (1.0 if kw == "gain" else v))
    want, outs = np_forward(params, x, arch.depth, **{kw: hook})
    got = gt.forward(params, jnp.asarray(x), {}, gt.Physics.create(s=None, test_scoped=c), arch, taps=True)
    for g, w in zip(got.taps, outs):
        np.testing.assert_allclose(np.asarray(g), w, rtol=1e-12, atol=1e-12)
    if layers in ("hidden", "output"):  # these scopes need the depth; the dispatchers say so
        phys = gt.Physics.create(s=None, test_scoped=c)
        call = {"weights": lambda: phys.effective_weights(jnp.ones((2, 2)), 1),
                "bias": lambda: phys.bias(jnp.ones(2), 1),
                "gain": lambda: phys.gain({}, 1, None, (2,)),
                "activation": lambda: phys.activation(jnp.ones(2), jnp.tanh, 1),
                "readout": lambda: phys.readout(jnp.ones(2), {}, 1)}[stage]
        with pytest.raises(ValueError, match="depth"):
            call()


def test_plugin_fields_without_defaults_take_defaults(tmp_path):
    path = write(tmp_path, """
        from gift_theory.effects import Effect, register

        @register
        class Tilt(Effect):
            a: float = 0.5
            t: float
            name = "test_tilt"
            params = ("a", "t")
            defaults = {"a": 0.5, "t": 0.25}
            stage = "readout"
            mechanism = "readout_nonlinearity"

            def readout(self, v, noise, layer):
                return v + self.a * self.t
        """)
    assert fx.load_plugin(path) == ["test_tilt"]
    e = gt.make_effect("test_tilt")
    assert (e.a, e.t) == (0.5, 0.25) and fx.REGISTRY["test_tilt"]().t == 0.25
    assert gt.parse_effect("test_tilt=1,2").param_dict() == {"a": 1.0, "t": 2.0}


# ---- per-neuron parameters ---------------------------------------------------------------

def _per_neuron_class(scope="all"):
    @fx.register
    class Offsets(fx.Effect):
        delta: float = 0.0
        name = "test_offsets"
        params = ("delta",)
        bounds = {"delta": (-1.0, 1.0)}
        shape = {"delta": "neurons"}
        stage = "bias"
        layers = scope
        mechanism = "bias_offset"

        def bias(self, b, layer):
            return b + self.value("delta", layer)

    return Offsets


def test_per_neuron_scalar_arrays_json_replace_validate(x64):
    _per_neuron_class()
    arch, params, x = net((3, 4, 5, 2))
    deltas = (np.linspace(-0.2, 0.2, 4), np.linspace(0.3, -0.3, 5), np.array([0.1, -0.1]))
    # a scalar is every neuron's value
    scalar = gt.Physics.create(s=None, test_offsets=0.05)
    want, _ = np_forward(params, x, 3, bias=lambda b, l: b + 0.05)
    np.testing.assert_allclose(np.asarray(gt.forward(params, x, {}, scalar, arch).y), want, rtol=1e-12)
    # expand: one array per layer filled with the scalar -> the same numbers
    wide = scalar.expand(arch)
    assert [np.asarray(r).shape for r in wide.params()["delta"]] == [(4,), (5,), (2,)]
    np.testing.assert_allclose(np.asarray(gt.forward(params, x, {}, wide, arch).y), want, rtol=1e-12)
    # one array per layer
    phys = gt.Physics.create(s=None, test_offsets=dict(delta=[list(d) for d in deltas])).validate(arch=arch)
    want, _ = np_forward(params, x, 3, bias=lambda b, l: b + deltas[l - 1])
    np.testing.assert_allclose(np.asarray(gt.forward(params, x, {}, phys, arch).y), want, rtol=1e-12)
    js = phys.params_json()["delta"]
    assert isinstance(js, list) and [len(r) for r in js] == [4, 5, 2]
    np.testing.assert_allclose(js[1], deltas[1])
    assert "per-neuron" in phys.describe()
    again = scalar.replace(delta=[np.asarray(d) for d in deltas])  # replace accepts arrays
    np.testing.assert_allclose(np.asarray(gt.forward(params, x, {}, again, arch).y), want, rtol=1e-12)
    assert isinstance(again.params()["delta"], tuple)
    # bounds apply to every element; counts and lengths against the architecture
    with pytest.raises(gt.GiftInputError, match=r"layer 2 neuron 3: 1.5 is outside"):
        gt.make_effect("test_offsets", delta=[[0.0] * 4, [0, 0, 1.5, 0, 0], [0, 0]])
    with pytest.raises(gt.GiftInputError, match="3 values for 4 neurons"):
        gt.make_effect("test_offsets", delta=[[0.0] * 3, [0.0] * 5, [0.0] * 2]).validate(arch=arch)
    with pytest.raises(gt.GiftInputError, match="2 per-layer arrays"):
        gt.make_effect("test_offsets", delta=[[0.0] * 4, [0.0] * 5]).validate(arch=arch)
    with pytest.raises(gt.GiftInputError, match="must be a number"):
        gt.make_effect("shot", q=[[0.1]])  # only a 'neurons' parameter takes arrays


def test_per_neuron_scope_ignores_other_layers(x64):
    _per_neuron_class("hidden")
    arch, params, x = net((3, 4, 5, 2))
    wide = gt.Physics.create(s=None, test_offsets=0.1).expand(arch)
    assert [np.asarray(r).shape for r in wide.params()["delta"]] == [(4,), (5,), (0,)]
    wide.validate(arch=arch)
    want, _ = np_forward(params, x, 3, bias=lambda b, l: b + 0.1 if l < 3 else b)
    np.testing.assert_allclose(np.asarray(gt.forward(params, x, {}, wide, arch).y), want, rtol=1e-12)


@pytest.mark.slow
def test_per_neuron_parameters_under_jit_and_grad(x64):
    _per_neuron_class()
    arch, params, x = net((3, 4, 5, 2))
    phys = gt.Physics.create(s=0.1, test_offsets=0.0).expand(arch)
    noise = gt.sample_noise(jax.random.PRNGKey(3), arch, phys, (6,), jnp.float64)
    xj = jnp.asarray(x)

    def loss(deltas):
        ph = phys.replace(delta=deltas)
        return jnp.sum(gt.forward(params, xj, noise, ph, arch).y ** 2)

    rng = np.random.default_rng(0)
    deltas = tuple(jnp.asarray(rng.normal(0, 0.1, w)) for w in arch.widths[1:])
    g = jax.jit(jax.grad(loss))(deltas)
    assert [a.shape for a in g] == [(4,), (5,), (2,)]
    assert all(np.isfinite(np.asarray(a)).all() for a in g)
    jloss = jax.jit(loss)
    np.testing.assert_allclose(float(jloss(deltas)), float(loss(deltas)), rtol=1e-12)
    h = 1e-6
    for l in range(3):
        for i in range(arch.widths[l + 1]):
            up = tuple(d.at[i].add(h) if k == l else d for k, d in enumerate(deltas))
            dn = tuple(d.at[i].add(-h) if k == l else d for k, d in enumerate(deltas))
            fd = (float(jloss(up)) - float(jloss(dn))) / (2 * h)
            assert abs(fd - float(g[l][i])) < 1e-6 * max(1.0, abs(fd))
    # the gradient through the whole physics pytree reaches the per-neuron leaves too
    gp = jax.grad(lambda ph: jnp.sum(gt.forward(params, xj, noise, ph, arch).y ** 2))(phys.replace(delta=deltas))
    np.testing.assert_allclose(np.asarray(gp.get("test_offsets").delta[1]), np.asarray(g[1]), rtol=1e-10)


# ---- bad plugins ---------------------------------------------------------------------------

def _plugin(body, header="from gift_theory.effects import Effect, register\n"):
    return header + textwrap.dedent(body)


GOOD = """
@register
class Good(Effect):
    c: float = 0.0
    name = "test_good"
    params = ("c",)
    stage = "bias"
    mechanism = "bias_offset"
    def bias(self, b, layer):
        return b + self.c
"""


def _variant(**changes):
    """GOOD with class-body lines replaced: {old line fragment: new line}."""
    text = GOOD
    for old, new in changes.items():
        assert old in text, old
        text = text.replace(old, new)
    return _plugin(text)


BAD = {
    "syntax": ("from gift_theory.effects import Effect, register\nclass X(Effect)\n    pass\n",
               r"line 2: (invalid syntax|expected ':')"),
    "raises": (_plugin("x = 1\ny = 1 / 0\n"), r"line 3: importing it raised ZeroDivisionError: division by zero"),
    "no effect": (_plugin("class X(Effect):\n    name = 'x'\n"), r"registers no effect"),
    "clash": (_variant(**{'"test_good"': '"shot"'}), r"effect 'shot' \(class Good\) clashes with the built-in effect shot"),
    "missing hook": (_variant(**{'stage = "bias"': 'stage = "activation"'}),
                     r"effect test_good \(class Good\): stage 'activation' needs an activation\(z, sigma, layer\) method"),
    "law hook": (_variant(**{'stage = "bias"': 'stage = "law"'}), r"stage 'law' needs a standard\(key, shape, dtype\)"),
    "level": (_variant(**{'stage = "bias"': 'stage = "level"'}), r"stage 'level' is awgn's"),
    "stage": (_variant(**{'stage = "bias"': 'stage = "offset"'}), r"stage='offset' must be one of level, law"),
    "no stage": (_variant(**{'    stage = "bias"\n': ''}), r"stage=None must be one of"),
    "mechanism": (_variant(**{'mechanism = "bias_offset"': 'mechanism = "heat"'}), r"mechanism='heat' must be one of"),
    "no mechanism": (_variant(**{'    mechanism = "bias_offset"\n': ''}), r"needs a class attribute `mechanism`"),
    "no name": (_variant(**{'    name = "test_good"\n': ''}), r"effect class Good: needs a class attribute `name`"),
    "name type": (_variant(**{'name = "test_good"': 'name = 3'}), r"effect class Good: needs a class attribute `name`"),
    "param not a field": (_variant(**{'params = ("c",)': 'params = ("c", "d")'}),
                          r"parameter 'd' in params is not a dataclass field"),
    "field not a param": (_variant(**{'params = ("c",)': 'params = ()'}), r"field 'c' is neither in params"),
    "bounds key": (_variant(**{'params = ("c",)': 'params = ("c",)\n    bounds = {"k": (0, 1)}'}),
                   r"bounds names 'k', which is not in params"),
    "layers": (_variant(**{'params = ("c",)': 'params = ("c",)\n    layers = "middle"'}), r"layers='middle' must be"),
    "layers zero": (_variant(**{'params = ("c",)': 'params = ("c",)\n    layers = (0, 2)'}), r"layers=\(0, 2\) must be"),
    "shape value": (_variant(**{'params = ("c",)': 'params = ("c",)\n    shape = {"c": "weights"}'}),
                    r"a parameter's shape is 'neurons' or 'layers'"),
    "shape key": (_variant(**{'params = ("c",)': 'params = ("c",)\n    shape = {"d": "neurons"}'}),
                  r"shape names 'd', which is not in params"),
    "activation output": (_plugin("""
        @register
        class A(Effect):
            name = "test_a"
            stage = "activation"
            layers = "output"
            mechanism = "activation_mismatch"
            def activation(self, z, sigma, layer):
                return sigma(z)
        """), r"acts on hidden layers only"),
    "half registered": (_plugin(GOOD) + textwrap.dedent("""
        @register
        class Second(Effect):
            name = "test_second"
            stage = "weights"
            mechanism = "weight_error"
        """), r"effect test_second \(class Second\): stage 'weights' needs a weights\(W, layer\) method"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_plugin_is_one_line_naming_the_file(tmp_path, case):
    text, pattern = BAD[case]
    path = write(tmp_path, text, "my_effect.py")
    before = dict(fx.REGISTRY)
    with pytest.raises(gt.GiftInputError) as err:
        fx.load_plugin(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert __import__("re").search(pattern, msg), msg
    assert fx.REGISTRY == before  # nothing half-registered
    # the fixed file then loads (a failed load leaves nothing behind that blocks it)
    if case in ("half registered", "missing hook"):
        write(tmp_path, _plugin(GOOD), "my_effect.py")
        assert fx.load_plugin(path) == ["test_good"]


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(gt.GiftInputError, match=r"nope\.py: no such file$"):
        fx.load_plugin(tmp_path / "nope.py")
    with pytest.raises(gt.GiftInputError, match="not a file"):
        fx.load_plugin(tmp_path)


def test_register_rules_directly():
    class NotAnEffect:
        name = "x"

    with pytest.raises(gt.GiftInputError, match="not a subclass"):
        fx.register(NotAnEffect)

    class Shot2(fx.Effect):
        name = "shot"
        stage = "readout"
        mechanism = "input_dependent_noise"

        def readout(self, v, noise, layer):
            return v

    with pytest.raises(gt.GiftInputError, match=r"^effect 'shot' \(class Shot2\) clashes with the built-in effect shot$"):
        fx.register(Shot2)
    assert fx.REGISTRY["shot"] is fx.Shot


def test_two_files_same_stem_do_not_collide(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    p1 = write(tmp_path / "a", _plugin(GOOD), "fx.py")
    p2 = write(tmp_path / "b", _variant(**{'"test_good"': '"test_good2"'}), "fx.py")
    assert fx.load_plugin(p1) == ["test_good"] and fx.load_plugin(p2) == ["test_good2"]
    # the same name from another file is a clash naming the first file's module
    p3 = write(tmp_path, _plugin(GOOD), "other.py")
    with pytest.raises(gt.GiftInputError, match=r"other\.py: effect 'test_good' \(class Good\) clashes with the effect "
                                                r"test_good registered by .*/a/fx\.py$"):
        fx.load_plugin(p3)


# ---- entry points ------------------------------------------------------------------------------

def test_entry_points(tmp_path, monkeypatch):
    write(tmp_path, _plugin(GOOD), "gift_ep_mod.py")
    write(tmp_path, ACT_GAIN.replace("@register\n", ""), "gift_ep_cls.py")
    write(tmp_path, "value = 3\n", "gift_ep_bad.py")
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = [importlib.metadata.EntryPoint("mod", "gift_ep_mod", "gift.effects"),
           importlib.metadata.EntryPoint("cls", "gift_ep_cls:ActGain", "gift.effects")]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: eps if group == "gift.effects" else [])
    monkeypatch.setattr(_plugins, "_LOADED_EP", {})
    assert fx.load_entry_points() == ["test_good", "act_gain"]
    assert fx.load_entry_points() == ["test_good", "act_gain"]  # twice is harmless
    assert gt.Physics.create(s=0.1, act_gain=2.0, test_good=0.1).names == ("awgn", "test_good", "act_gain")
    eps.append(importlib.metadata.EntryPoint("bad", "gift_ep_bad:value", "gift.effects"))
    with pytest.raises(gt.GiftInputError, match=r"^entry point bad \(gift_ep_bad:value\): names a int"):
        fx.load_entry_points()
    eps[-1] = importlib.metadata.EntryPoint("gone", "gift_ep_missing", "gift.effects")
    with pytest.raises(gt.GiftInputError, match=r"^entry point gone \(gift_ep_missing\): loading it raised "
                                                r"ModuleNotFoundError"):
        fx.load_entry_points()
