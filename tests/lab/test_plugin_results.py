"""A plugin's hooks are checked where they return (reference §2b): a result of the wrong shape,
dtype or with a non-finite value is a bad input naming the file, the effect and the hook -- in
``simulate``, ``fit`` and ``compare`` alike; a hook that takes ``t`` gets the file's times or
the command refuses; a ``layers`` scope outside the network is refused. The property test draws
the fault (where and what) at random; every one must give exit 2 and one line."""

import json
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gift_theory as gt
from gift_theory import effects as fx
from gift_theory.cli import main

HEAD = "import jax.numpy as jnp\nfrom gift_theory.effects import Effect, register\n\n"


def plugin(tmp_path, name, stage, body, layers="all", file=None):
    """A one-parameter plugin ``name`` of ``stage`` whose hook returns ``body`` (an expression)."""
    sig = {"readout": "readout(self, v, noise, layer)", "weights": "weights(self, W, layer)",
           "bias": "bias(self, b, layer)", "activation": "activation(self, z, sigma, layer)",
           "bias_t": "bias(self, b, layer, t)"}[stage]
    path = tmp_path / (file or f"{name}.py")
    path.write_text(HEAD + textwrap.dedent(f'''
        @register
        class P_{name}(Effect):
            g: float = 1.0
            name = "{name}"
            params = ("g",)
            bounds = {{"g": (-10.0, 10.0)}}
            defaults = {{"g": 1.0}}
            stage = "{stage.split('_')[0]}"
            mechanism = "readout_nonlinearity"
            layers = {layers!r}

            def {sig}:
                return {body}
        '''))
    return str(path)


@pytest.fixture(autouse=True)
def clean_registry():
    before = dict(fx.REGISTRY)
    yield
    fx.REGISTRY.clear()
    fx.REGISTRY.update(before)


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line(err):
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def meas_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("m")
    assert main(["simulate", "--arch", "3-5-2", "--inputs", "16", "--shots", "8", "--out", str(d / "m.npz"),
                 "--json"]) == 0
    return str(d / "m.npz")


@pytest.mark.slow
def test_a_hook_returning_nan_is_named_in_simulate_and_nothing_is_written(tmp_path, capsys):
    p = plugin(tmp_path, "nanout", "readout", "v * jnp.nan")
    out = tmp_path / "sim.npz"
    code, so, err = run(capsys, "simulate", "--plugin", p, "--arch", "3-5-2", "--inputs", "8", "--effect", "nanout",
                        "--out", str(out), "--json")
    line = one_line(err)
    assert code == 2 and so == "" and not out.exists()
    assert "nanout.py: effect nanout (class P_nanout), hook readout(v, noise, layer): returned nan" in line


def test_a_hook_returning_nan_is_named_in_fit_not_fitted_around(tmp_path, capsys, meas_file):
    p = plugin(tmp_path, "nanfit", "readout", "v * jnp.nan")
    code, so, err = run(capsys, "fit", meas_file, "--plugin", p, "--add", "nanfit", "--json", "--quiet",
                        "--replicates", "2", "--power-replicates", "0")
    assert code == 2 and so == ""
    assert "effect nanfit (class P_nanfit), hook readout(v, noise, layer): returned nan" in one_line(err)


@pytest.mark.parametrize("stage, body, want", [
    ("readout", "v[..., None]", "returned shape (8, 64, 5, 1), expected (8, 64, 5)"),
    ("weights", "W.T", "hook weights(W, layer): returned shape (3, 5), expected (..., 5, 3)"),
    ("bias", "jnp.zeros(7)", "returned shape (7,)"),
    ("activation", "(sigma(z) > 0)", "returned dtype bool"),
])
def test_a_hook_result_of_the_wrong_shape_or_dtype_is_named(tmp_path, capsys, stage, body, want):
    p = plugin(tmp_path, f"bad_{stage}", stage, body, layers=(1,))
    code, so, err = run(capsys, "simulate", "--plugin", p, "--arch", "3-5-2", "--inputs", "8",
                        "--effect", f"bad_{stage}", "--out", str(tmp_path / "s.npz"), "--json")
    line = one_line(err)
    assert code == 2 and f"effect bad_{stage}" in line and want in line, line


def test_a_hook_taking_t_needs_times(tmp_path, capsys, meas_file):
    p = plugin(tmp_path, "tdrift", "bias_t", "b + self.g * t")
    # compare --effect on a file without times: refused (no silent t = 0)
    code, so, err = run(capsys, "compare", meas_file, "--plugin", p, "--effect", "awgn=0.1", "--effect",
                        "tdrift=0.5", "--json", "--power-replicates", "0")
    assert code == 2 and "tdrift" in one_line(err) and "no acquisition times t" in err
    # simulate records the times such an effect acts through, and they move the shots
    out = tmp_path / "t.npz"
    code, so, err = run(capsys, "simulate", "--plugin", p, "--arch", "3-5-2", "--inputs", "8", "--effect",
                        "tdrift=0.5", "--out", str(out), "--json")
    assert code == 0 and json.loads(so)["times"] is True
    with np.load(out) as f:
        assert "t" in f.files and f["t"].max() == 1.0


def test_layers_outside_the_network_are_refused(tmp_path, capsys, meas_file):
    p = plugin(tmp_path, "far", "readout", "self.g * v", layers=(7,))
    code, so, err = run(capsys, "simulate", "--plugin", p, "--arch", "3-5-2", "--inputs", "8", "--effect", "far=2",
                        "--out", str(tmp_path / "s.npz"), "--json")
    assert code == 2 and "layers=(7,) names layer 7, but the network has 2 layers" in one_line(err)
    for args in (["diagnose", meas_file, "--plugin", p, "--json", "--quiet"],
                 ["fit", meas_file, "--plugin", p, "--add", "far", "--json", "--quiet"],
                 ["compare", meas_file, "--plugin", p, "--effect", "awgn=0.1", "--effect", "far=2", "--json"]):
        code, so, err = run(capsys, *args)
        assert code == 2 and so == "" and "names layer 7" in one_line(err), args
    # an activation hook on the output layer alone acts on nothing: refused too
    q = plugin(tmp_path, "outact", "activation", "sigma(z)", layers=(2,))
    code, so, err = run(capsys, "simulate", "--plugin", q, "--arch", "3-5-2", "--inputs", "8", "--effect", "outact",
                        "--out", str(tmp_path / "s.npz"), "--json")
    assert code == 2 and "no layer of this 2-layer network" in one_line(err)


FAULTS = {
    "nan": "v.at[{i}].set(jnp.nan)",
    "inf": "v.at[{i}].set(jnp.inf)",
    "minus_inf": "v.at[{i}].set(-jnp.inf)",
    "extra_axis": "v[..., None]",
    "dropped_axis": "v[..., 0]",
    "wrong_width": "jnp.concatenate([v, v], axis=-1)",
    "complex": "v + 1j",
    "not_an_array": "'v'",
}


@pytest.mark.slow
@settings(max_examples=12, deadline=None)
@given(fault=st.sampled_from(sorted(FAULTS)), where=st.integers(0, 7), layer=st.sampled_from(["all", (1,), (2,)]))
def test_any_broken_hook_result_is_a_bad_input_naming_the_hook(tmp_path_factory, fault, where, layer):
    """The plugin contract as a property: whatever a readout hook returns wrong, on whichever
    layer and input, simulation raises one GiftInputError naming the file, effect and hook."""
    tmp = tmp_path_factory.mktemp("p")
    name = f"f_{fault}"
    body = FAULTS[fault].format(i=f"({where}, 0, 0)")
    path = plugin(tmp, name, "readout", body, layers=layer)
    before = dict(fx.REGISTRY)
    try:
        fx.load_plugin(path)
        arch = gt.Architecture((3, 5, 2))
        params = gt.init_params(__import__("jax").random.PRNGKey(0), arch)
        x = np.linspace(0, 1, 8 * 3).reshape(8, 3)
        with pytest.raises(gt.GiftInputError) as err:
            gt.lab.simulate_measurement(__import__("jax").random.PRNGKey(1), params, x,
                                        gt.Physics.parse([name], s=0.1), shots=4)
        msg = str(err.value)
        assert "\n" not in msg and f"{name}.py: effect {name} (class P_{name}), hook readout(v, noise, layer)" in msg
    finally:
        fx.REGISTRY.clear()
        fx.REGISTRY.update(before)
