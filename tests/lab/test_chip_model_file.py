"""A fitted chip as a file (reference §7b) and the preset chips (§2c), through the commands.

`gift fit --save-model` writes the fitted model; `gift simulate --chip-model` draws from it and
records the programmed weights; `gift compare --chip-model` scores it; `Physics.load` reads it.
"""

import json

import numpy as np
import pytest

import gift_theory as gt
from gift_theory.cli import main


def _run(capsys, *argv):
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


def _json(capsys, *argv):
    rc, out, err = _run(capsys, *argv, "--json")
    assert rc == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A chip with per-device weight errors, measured with taps, fitted with weight_error and saved."""
    import contextlib
    import io

    d = tmp_path_factory.mktemp("chipmodel")
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["simulate", "--arch", "8-12-6", "--inputs", "60", "--shots", "16", "--effect", "awgn=0.05",
                     "--effect", "weight_error=e:0.05,seed:3", "--taps", "--out", str(d / "chip.npz")]) == 0
    with np.load(d / "chip.npz") as f:
        np.savez(d / "w.npz", **{k: f[k] for k in f.files if k[:1] in "Wb"})
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["fit", str(d / "chip.npz"), "--add", "weight_error", "--quiet", "--replicates", "2",
                     "--power-replicates", "0", "--save-model", str(d / "m.chip.npz"), "--json"]) == 0
    return d, json.loads(buf.getvalue())


@pytest.mark.slow
def test_fit_saves_the_model_it_reports(fitted):
    d, fit = fitted
    assert fit["chip_model"] == str(d / "m.chip.npz")
    # the ladder's comparison, fitted model first, says which rung the data reject
    assert [(r["model"], r["status"]) for r in fit["model_comparison"]] == [
        ("awgn + weight_error", "passes" if fit["p_value_after"] >= 0.01 else "fails"), ("awgn", "fails")]
    assert fit["p_value_after"] >= 0.01
    from gift_theory.calibration import load_chip_model

    cm = load_chip_model(fit["chip_model"])
    assert cm.physics.s == pytest.approx(fit["params"]["s"], rel=1e-12)
    assert gt.Physics.load(fit["chip_model"]).names == ("awgn",)  # the offsets live in the maps, not the noise
    assert cm.intervals["s"] == pytest.approx(fit["intervals"]["s"])
    assert [r.layer for r in cm.responses] == [1, 2]  # weight_error's fitted offsets on both layers
    with np.load(d / "chip.npz") as f:
        W1 = f["W1"]
    r1 = cm.responses[0]
    np.testing.assert_allclose(r1.prog_W, W1, atol=1e-6)
    # realised = programmed + offset, for any programming
    W_new = np.ones_like(W1)
    got = cm.realise(((W_new, np.zeros(W1.shape[0])), (np.ones_like(cm.responses[1].prog_W),
                                                       np.zeros(cm.responses[1].prog_b.shape))))
    np.testing.assert_allclose(np.asarray(got[0].W), W_new + (r1.eff_W - r1.prog_W), atol=1e-12)


@pytest.mark.slow
def test_simulate_draws_from_the_model_and_compare_scores_it(fitted, capsys, tmp_path):
    d, fit = fitted
    out = tmp_path / "again.npz"
    sim = _json(capsys, "simulate", "--chip-model", fit["chip_model"], "--weights", str(d / "w.npz"), "--taps",
                "--inputs", "60", "--shots", "16", "--seed", "5", "--out", str(out))
    assert sim["chip_model"] == fit["chip_model"] and sim["realised_layers"] == [1, 2]
    assert sim["params"]["s"] == pytest.approx(fit["params"]["s"])
    with np.load(out) as f, np.load(d / "w.npz") as w:  # the file records what was programmed
        np.testing.assert_allclose(f["W1"], w["W1"], atol=1e-6)
    model = _json(capsys, "compare", str(out), "--chip-model", fit["chip_model"], "--power-replicates", "0")
    plain = _json(capsys, "compare", str(out), "--effect", f"awgn={fit['params']['s']}", "--power-replicates", "0")
    assert model["p_value"] >= 0.01, model  # the file drawn from the model is the model's
    assert plain["p_value"] < 0.01, plain  # without the saved offsets the same noise fails: they were carried


def test_presets_start_a_simulation_and_effect_changes_a_level(capsys, tmp_path):
    p = gt.Physics.preset("coherent-mzi-mesh")
    assert {"awgn", "weight_error", "crosstalk", "shot", "quantization"} == set(p.names)
    assert gt.Physics.preset("incoherent-intensity", s=0.07).s == pytest.approx(0.07)
    sim = _json(capsys, "simulate", "--preset", "incoherent-intensity", "--effect", "shot=0.03", "--arch", "4-5-3",
                "--inputs", "8", "--shots", "4", "--out", str(tmp_path / "p.npz"))
    assert sim["preset"] == "incoherent-intensity" and sim["params"]["q"] == pytest.approx(0.03)
    assert sim["params"]["c"] == pytest.approx(gt.effects.PRESETS["incoherent-intensity"]["effects"]["common_mode"]["c"])


@pytest.mark.parametrize("argv, what", [
    (["simulate", "--preset", "nope", "--arch", "4-5-3", "--out", "{tmp}/x.npz"], "unknown preset 'nope'"),
    (["simulate", "--preset", "coherent-mzi-mesh", "--chip-model", "{model}", "--out", "{tmp}/x.npz"], "give one"),
    (["simulate", "--chip-model", "{model}", "--arch", "8-10-6", "--out", "{tmp}/x.npz"], "a model of a 8-12-6"),
    (["simulate", "--chip-model", "{tmp}/none.chip.npz", "--out", "{tmp}/x.npz"], "no such chip model"),
    (["fit", "{meas}", "--add", "shot", "--save-model", "{tmp}/m.txt"], "written as .npz"),
    (["fit", "{meas}", "--add", "shot", "--save-model", "{tmp}/no/m.npz"], "does not exist"),
])
def test_bad_chip_model_arguments_are_one_line_and_exit_2(fitted, capsys, tmp_path, argv, what):
    d, fit = fitted
    argv = [a.format(tmp=tmp_path, model=fit["chip_model"], meas=d / "chip.npz") for a in argv]
    rc, out, err = _run(capsys, *argv)
    assert rc == 2 and what in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.npz").exists() and not (tmp_path / "m.txt").exists()


def test_a_model_that_needs_an_unloaded_plugin_names_it(tmp_path):
    from gift_theory.calibration import ChipModel, load_chip_model

    m = ChipModel((4, 5, 3), "tanh", (), ({"name": "awgn", "params": {"s": 0.05}},
                                          {"name": "my_detector", "params": {"beta": 0.1}}), "test",
                  plugins=("my_detector",))
    path = m.save(str(tmp_path / "p.chip.npz"))
    with pytest.raises(gt.GiftInputError, match="my_detector is not registered: load the plugin"):
        load_chip_model(path)
