"""Calibration: each layer's realised map read off the shots, and the closed loop that makes a chip
realise the trained network -- against chips written here in plain numpy from the contract's text."""

import json
import os
import pathlib
import re

import jax
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.calibration import calibrate, fit_layers
from gift_theory.chips import Ledger, Measurement, uncharged
from gift_theory.data import Teacher, load_dataset
from gift_theory.finetune import make_problem

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TEACHER = Teacher((4, 8, 2))
S = 0.05


class FixedErrorChip:
    """Contract §1-§2 with fixed per-device errors, in numpy: layer gains, stuck weights (an entry
    realised at 0 whatever is programmed), hidden bias offsets, output detectors' gains and offsets,
    and optionally a fresh random map error for every programming other than the first one
    (``chaotic``: no calibration through the weights can follow it)."""

    def __init__(self, gains=(1.0, 1.0), stuck=(), delta=None, det_gain=None, det_offset=None, chaotic=0.0, taps=True,
                 seed=0):
        self.widths = TEACHER.widths
        self.ledger = Ledger()
        self.gains, self.stuck, self.delta = gains, stuck, delta
        self.det_gain, self.det_offset, self.chaotic, self.taps = det_gain, det_offset, chaotic, taps
        self.rng = np.random.default_rng(seed)
        self.first = None

    def realised(self, params):
        Ws = [np.array(W, np.float64) for W, _ in params]
        bs = [np.array(b, np.float64) for _, b in params]
        key = tuple(np.round(np.concatenate([W.ravel() for W in Ws]), 7))
        if self.chaotic and self.first is not None and key != self.first:
            Ws = [W + self.chaotic * np.random.default_rng(abs(hash(key)) % 2**32).standard_normal(W.shape) for W in Ws]
        if self.first is None:
            self.first = key
        for (l, i, j) in self.stuck:
            Ws[l][i, j] = 0.0
        Ws = [g * W for g, W in zip(self.gains, Ws)]
        if self.delta is not None:
            bs[0] = bs[0] + self.delta
        return Ws, bs

    def forward(self, params, x, shots, rng):
        Ws, bs = self.realised(params)
        a = np.asarray(x, np.float64)[:, None, :] + S * rng.standard_normal((len(x), shots, x.shape[1]))
        z1 = a @ Ws[0].T + bs[0] + S * rng.standard_normal((len(x), shots, 8))
        a1 = np.tanh(z1) + S * rng.standard_normal(z1.shape)
        y = a1 @ Ws[1].T + bs[1] + S * rng.standard_normal((len(x), shots, 2))
        if self.det_gain is not None:
            y = self.det_gain * y + self.det_offset
        return y, a1

    def measure(self, params, x, shots, *, taps=False, key=None):
        self.ledger.charge(len(x) * shots)
        y, a1 = self.forward(params, np.asarray(x), shots, self.rng)
        return Measurement(np.asarray(x, np.float64), y, tuple(gt.Layer(np.asarray(W), np.asarray(b)) for W, b in params),
                           (a1,) if taps and self.taps else None)


@pytest.fixture(scope="module")
def setting():
    ds = load_dataset("teacher", widths=TEACHER.widths, n_train=600, n_test=300)
    w0 = TEACHER.params()
    return ds, w0


def _problem(setting, chip, budget=40.0, seed=0):
    ds, w0 = setting
    return make_problem(gt.Architecture(TEACHER.widths), w0, ds.x_train, ds.y_train, s0=S, true_physics=None,
                        budget=budget, K1=500, seed=seed, chip=chip)


def _true_loss(chip, params, ds, shots=64):
    y, _ = chip.forward(params, ds.x_test, shots, np.random.default_rng(99))
    return float(np.mean(np.sum((y - ds.y_test[:, None, :]) ** 2, -1)))


def test_fit_layers_reads_the_realised_map_within_its_standard_errors(setting):
    """With taps, each layer's posterior mean sits within its standard errors of the realised map
    (z-scores of mean square near 1, pooled over six chips: the entries of one neuron are
    correlated, so one chip's 18 output z-scores are too few), and far closer to it than the
    programmed map is."""
    ds, w0 = setting
    z2 = {1: [], 2: []}
    for seed in range(6):
        chip = FixedErrorChip(gains=(0.7, 1.0), delta=np.array([0.4, 0, 0, 0, -0.3, 0, 0, 0]),
                              det_gain=np.array([1.3, 0.8]), det_offset=np.array([0.3, -0.2]), seed=seed)
        meas = chip.measure(w0, ds.x_train[:400], 16, taps=True)
        fits = fit_layers(meas)
        Ws, bs = chip.realised(w0)
        truth = [(Ws[0], bs[0]), (chip.det_gain[:, None] * Ws[1], chip.det_gain * bs[1] + chip.det_offset)]
        for f, (W, b) in zip(fits, truth):
            z2[f.layer].append(np.concatenate([((f.W - W) / f.W_se).ravel(), (f.b - b) / f.b_se]) ** 2)
            off = np.concatenate([(W - f.W_prog).ravel(), b - f.b_prog])
            err = np.concatenate([(f.W - W).ravel(), f.b - b])
            assert np.sqrt(np.mean(err ** 2)) < 0.2 * np.sqrt(np.mean(off ** 2))
        assert abs(fits[0].s / S - 1) < 0.1 and abs(fits[1].s / (S * np.sqrt(np.mean(chip.det_gain ** 2))) - 1) < 0.15
    for layer, v in z2.items():
        assert 0.4 < np.mean(v) < 2.0, (layer, np.mean(v))


def test_fit_layers_without_taps_reads_the_output_map(setting):
    ds, w0 = setting
    chip = FixedErrorChip(det_gain=np.array([1.3, 0.8]), det_offset=np.array([0.3, -0.2]), taps=False)
    meas = chip.measure(w0, ds.x_train[:400], 16, taps=True)
    assert not meas.has_taps
    (f,) = fit_layers(meas)
    assert f.layer == 2
    np.testing.assert_allclose(f.b, chip.det_gain * np.asarray(w0[1].b) + chip.det_offset, atol=6 * f.b_se.max())
    np.testing.assert_allclose(f.W, chip.det_gain[:, None] * np.asarray(w0[1].W), atol=6 * f.W_se.max())


@pytest.mark.slow
def test_calibrate_recovers_gains_offsets_and_bias_shifts(setting):
    """Loss on layer 1, a bias current off, the detectors' gains and offsets: the loop programs
    weights under which the chip's loss is within noise of the ideal chip's, and the confirmation
    on the chip accepts them."""
    ds, w0 = setting
    chip = FixedErrorChip(gains=(0.7, 1.0), delta=np.array([0.4, 0, 0, 0, -0.3, 0, 0, 0]), det_gain=np.array([1.3, 0.8]),
                          det_offset=np.array([0.3, -0.2]))
    problem = _problem(setting, chip)
    params, info = calibrate(problem)
    ideal = _true_loss(FixedErrorChip(), w0, ds)
    before, after = _true_loss(chip, w0, ds), _true_loss(chip, params, ds)
    assert info["accepted"] and info["taps"]
    assert after - ideal < 0.05 * (before - ideal), (before, after, ideal)
    assert problem.evaluations_used() <= 40
    gains = info["identified"]["1"]["rows_gain_median"]
    assert abs(gains - 0.7) < 0.1
    # the chip's noise is awgn at s0: the gains and offsets are fixed maps, not read as noise
    assert info["noise"]["used"] == "awgn (it fits)", info["noise"]


@pytest.mark.slow
def test_calibrate_pins_stuck_weights_and_retrains_around_them(setting):
    ds, w0 = setting
    W1 = np.asarray(w0[0].W)
    big = np.argsort(-np.abs(W1).ravel())[:3]
    stuck = [(0, int(i // 4), int(i % 4)) for i in big]
    chip = FixedErrorChip(stuck=stuck)
    params, info = calibrate(_problem(setting, chip, budget=60))
    assert info["identified"]["1"]["stuck_weights"] >= 3 and info["retrained"] >= 1
    assert _true_loss(chip, params, ds) < _true_loss(chip, w0, ds)


def test_calibrate_never_returns_weights_the_chip_finds_worse(setting):
    """On a chip that realises w0 exactly but adds a fresh error of 0.3 to anything else programmed,
    no correction can help: the paired confirmation refuses, and w0 itself comes back."""
    ds, w0 = setting
    chip = FixedErrorChip(chaotic=0.3)
    params, info = calibrate(_problem(setting, chip))
    assert not info["accepted"]
    for a, b in zip(jax.tree_util.tree_leaves(params), jax.tree_util.tree_leaves(w0)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow
def test_identify_retrain_confirms_on_the_chip_before_returning(setting):
    """Detector gains and offsets are no noise; whatever identify-retrain reads them as, the weights
    it returns are not worse on the chip than w0 (the paired confirmation), and it says what it used."""
    ds, w0 = setting
    chip = FixedErrorChip(det_gain=np.array([1.6, 0.5]), det_offset=np.array([0.6, -0.5]))
    from gift_theory.finetune import identify_retrain
    params, info = identify_retrain(_problem(setting, chip, budget=20))
    assert "accepted" in info and info["used"]
    before, after = _true_loss(chip, w0, ds), _true_loss(chip, params, ds)
    assert after <= before + 3 * 0.01 * before


@pytest.mark.slow
def test_calibrate_without_taps_corrects_the_output_and_never_does_harm(setting):
    """Without taps: the output's detector gains and offsets are read and corrected; a hidden
    layer's loss is not read, and the diagnosis' alternative competes; the chip decides, and the
    result is never worse than w0."""
    ds, w0 = setting
    chip = FixedErrorChip(gains=(0.6, 1.0), det_gain=np.array([1.3, 0.8]), det_offset=np.array([0.3, -0.2]), taps=False)
    params, info = calibrate(_problem(setting, chip, budget=40))
    assert info["taps"] is False and info["not_identified"]
    before, after = _true_loss(chip, w0, ds), _true_loss(chip, params, ds)
    assert after < 0.5 * before, (before, after, info["returned"])


def test_uncharged_shots_are_not_held_against_the_budget():
    ledger = Ledger(100)
    ledger.charge(60)
    with uncharged(ledger):
        ledger.charge(500)
    assert ledger.shots == 60 and ledger.free_shots == 500 and ledger.budget_shots == 100
    ledger.charge(40)
    with pytest.raises(gt.chips.BudgetExceeded):
        ledger.charge(1)


# ---------------------------------------------------------------------------------------- the command
def _cli(capsys, *argv):
    from gift_theory.cli import main
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


def _page_blocks():
    page = pathlib.Path(ROOT, "docs", "hardware.md").read_text()
    return re.findall(r"```python\n(.*?)```", page, re.S)


def test_the_hardware_page_shows_the_example_driver_verbatim():
    assert pathlib.Path(ROOT, "docs", "examples", "my_chip.py").read_text() in _page_blocks()


@pytest.mark.slow
def test_the_hardware_pages_python_example_runs(monkeypatch, capsys):
    """The page's Python walk-through, as written: calibrate on the example driver, then a paired
    look at the result on fresh shots."""
    monkeypatch.chdir(ROOT)
    monkeypatch.setattr("sys.path", list(__import__("sys").path))
    (code,) = [b for b in _page_blocks() if "calibrate(problem)" in b]
    exec(compile(code, "docs/hardware.md", "exec"), {"__name__": "hardware_example"})
    out = capsys.readouterr().out
    assert "accepted" in out
    gain = float(re.search(r"Eval gain on fresh shots: ([-0-9.]+)", out).group(1))
    assert gain > 0.5


@pytest.mark.slow
@pytest.mark.parametrize("method", ["calibrate", "identify-retrain"])
def test_finetune_on_the_hardware_pages_driver(capsys, tmp_path, method):
    """docs/hardware.md's driver from the command line: the scores are the chip's, the weights go to --out."""
    out = str(tmp_path / "w.npz")
    rc, so, err = _cli(capsys, "finetune", "--dataset", "teacher", "--arch", "4-8-2", "--s0", "0.05", "--chip",
                       os.path.join(ROOT, "docs", "examples", "my_chip.py") + ":make_chip", "--method", method,
                       "--budget", "30", "--K1", "500", "--score-shots", "8", "--out", out, "--json")
    assert rc == 0, err
    r = json.loads(so)
    assert r["scored_by"] == "chip" and r["st"] is None and r["out"] == out and 1 <= r["in_situ_evaluations"] <= 30
    with np.load(out) as f:
        assert sorted(f.files) == ["W1", "W2", "b1", "b2"] and f["W1"].shape == (8, 4)
    if method == "calibrate":
        assert r["loss_after"] < 0.2 * r["loss_before"]


def _chip_file(tmp_path, body):
    p = tmp_path / "drv.py"
    p.write_text("import numpy as np\nfrom gift_theory.chips import Ledger, Measurement\n" + body)
    return str(p)


@pytest.mark.parametrize("body, name, what", [
    ("def make():\n    return 3\n", "make", "has no 'widths'"),
    ("x = 1\n", "make", "no callable 'make'"),
    ("raise RuntimeError('boom')\n", "make", "raised RuntimeError: boom"),
    ("class C:\n    widths = (4, 8, 2)\n    ledger = Ledger()\n    def measure(self, params, x, shots, *, taps=False, key=None):\n"
     "        self.ledger.charge(len(x) * shots)\n        y = np.zeros((len(x), shots, 2))\n"
     "        return Measurement(x, y, (np.zeros((len(x), shots, 8)),))\n"
     "def make():\n    return C()\n", "make", "not the 2 programmed (W, b) pairs"),
    ("class C:\n    widths = (4, 8, 2)\n    ledger = Ledger()\n    def measure(self, params, x, shots, *, taps=False, key=None):\n"
     "        self.ledger.charge(len(x) * shots)\n        return Measurement(x, np.zeros((len(x), 2)), params)\n"
     "def make():\n    return C()\n", "make", "expected"),
])
def test_a_chip_that_breaks_the_protocol_is_one_line_and_exit_2(capsys, tmp_path, setting, body, name, what):
    ds, w0 = setting
    wfile = str(tmp_path / "w0.npz")
    from gift_theory.training import save_weights
    save_weights(wfile, w0, {})
    rc, so, err = _cli(capsys, "finetune", "--dataset", "teacher", "--arch", "4-8-2", "--s0", "0.05", "--weights", wfile,
                       "--chip", _chip_file(tmp_path, body) + ":" + name, "--method", "calibrate", "--budget", "20",
                       "--K1", "200", "--json")
    assert rc == 2 and so == "", err
    assert what in err and len(err.strip().splitlines()) == 1 and "drv.py" in err


@pytest.mark.parametrize("argv, what", [
    (["--chip", "x.py:make", "--st", "0.1"], "--chip"),
    (["--method", "calibrate"], "--st"),
    (["--st", "0.1", "--out", "w.txt"], "--out"),
    (["--chip", "nofile.py:make"], "no such file"),
    (["--chip", "nocolon"], "FILE.py:NAME"),
])
def test_finetune_chip_arguments_bad_input(capsys, argv, what):
    rc, so, err = _cli(capsys, "finetune", "--s0", "0.05", *argv, "--json")
    assert rc == 2 and so == ""
    assert what in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_gift_calibrate_from_a_file_predicts_what_the_chip_then_realises(capsys, tmp_path, setting):
    """A lab with files and no driver: the corrected weights from one measurement, the predicted
    accuracy with its interval; programmed on the chip they realise that accuracy; a second
    measurement is scored against the saved chip model."""
    ds_small, w0 = setting
    ds = load_dataset("teacher")
    chip = FixedErrorChip(gains=(0.7, 1.0), det_gain=np.array([1.3, 0.8]), det_offset=np.array([0.3, -0.2]))
    from gift_theory.lab import save_measurement
    meas_path, out = str(tmp_path / "meas.npz"), str(tmp_path / "w.npz")
    save_measurement(meas_path, chip.measure(w0, ds.x_train[:400], 16, taps=True))
    # the noise named (--add awgn): the diagnosis' choice of it is noise_physics' test below
    rc, so, err = _cli(capsys, "calibrate", meas_path, "--dataset", "teacher", "--out", out, "--draws", "10",
                       "--add", "awgn", "--json")
    assert rc == 0, err
    r = json.loads(so)
    assert {"effects", "params", "predicted_accuracy", "predicted_accuracy_interval", "accuracy_before", "out"} <= set(r)
    lo, hi = r["predicted_accuracy_interval"]
    assert lo <= r["predicted_accuracy"] <= hi and r["predicted_accuracy"] > r["accuracy_before"] + 0.05
    with np.load(out) as f:
        corrected = [(f["W1"], f["b1"]), (f["W2"], f["b2"])]
    y, _ = chip.forward(corrected, ds.x_test, 32, np.random.default_rng(5))
    realised = float(np.mean(np.argmax(y, -1) == ds.labels_test[:, None]))
    assert abs(realised - r["predicted_accuracy"]) < 0.03, (realised, r["predicted_accuracy"])
    y0, _ = chip.forward(w0, ds.x_test, 32, np.random.default_rng(5))
    assert abs(float(np.mean(np.argmax(y0, -1) == ds.labels_test[:, None])) - r["accuracy_before"]) < 0.03
    new = str(tmp_path / "new.npz")
    save_measurement(new, chip.measure(corrected, ds.x_train[400:800], 16, taps=True))
    rc, so, err = _cli(capsys, "compare", new, "--chip-model", r["chip_model"], "--power-replicates", "0", "--json")
    assert rc == 0, err
    c = json.loads(so)
    assert c["model"]["chip_model"] == r["chip_model"] and not c["model"]["fitted"]
    assert c["per_layer"]["layer1"] < 5 * c["noise_floor"]  # layer 1's prediction (a loss) holds


def test_calibrate_takes_the_noise_of_a_saved_model_without_its_fixed_maps(capsys, tmp_path, setting):
    """--noise-model: the noise-like effects of a saved model are the chip's noise (nothing fitted);
    its fixed maps (crosstalk here) are left out, since the maps are read off the file."""
    from gift_theory.calibration import ChipModel
    from gift_theory.lab import save_measurement
    ds, w0 = setting
    chip = FixedErrorChip(gains=(0.8, 1.0))
    meas_path = str(tmp_path / "meas.npz")
    save_measurement(meas_path, chip.measure(w0, ds.x_train[:200], 8, taps=True))
    noise = ChipModel((4, 8, 2), "tanh", (), ({"name": "awgn", "params": {"s": 0.0437}},
                                              {"name": "crosstalk", "params": {"k": 0.03}},
                                              {"name": "shot", "params": {"q": 0.004}}), "test")
    model = noise.save(str(tmp_path / "noise.chip.npz"))
    rc, so, err = _cli(capsys, "calibrate", meas_path, "--dataset", "teacher", "--out", str(tmp_path / "w.npz"),
                       "--noise-model", model, "--no-retrain", "--draws", "2", "--json")
    assert rc == 0, err
    r = json.loads(so)
    assert r["effects"] == ["awgn", "shot"] and r["noise_model_dropped"] == ["crosstalk"]
    assert r["params"] == {"s": pytest.approx(0.0437), "q": pytest.approx(0.004)}
    rc, so, err = _cli(capsys, "calibrate", meas_path, "--dataset", "teacher", "--out", str(tmp_path / "w2.npz"),
                       "--noise-model", model, "--add", "shot")
    assert rc == 2 and "--noise-model and --add" in err and not os.path.exists(tmp_path / "w2.npz")


def test_a_chip_model_round_trips_and_refuses_a_file_that_is_not_one(tmp_path, setting):
    from gift_theory.calibration import ChipModel, LayerResponse, load_chip_model
    ds, w0 = setting
    W, b = (np.asarray(a, np.float64) for a in w0[1])
    r = LayerResponse(2, 1.1 * W, b + 0.2, W, b, np.full(2, 1.1), np.ones(2), 0.01 * np.ones_like(W), 0.01 * np.ones(2),
                      np.zeros(W.shape, bool), np.array([True, False]))
    m = ChipModel((4, 8, 2), "tanh", (r,), ({"name": "awgn", "params": {"s": 0.05}},), "test")
    path = m.save(str(tmp_path / "m.chip.npz"))
    back = load_chip_model(path)
    got = back.realise(w0)
    np.testing.assert_allclose(np.asarray(got[1].W), 1.1 * W)
    np.testing.assert_allclose(np.asarray(got[1].b), [b[0] + 0.2, b[1] + 0.2])
    np.testing.assert_array_equal(np.asarray(got[0].W), np.asarray(w0[0].W))
    assert back.physics.s == pytest.approx(0.05)
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(gt.GiftInputError, match="not a gift chip model"):
        load_chip_model(str(bad))


@pytest.mark.slow
def test_the_demos_calibration_part_recovers_the_lost_accuracy():
    """gift demo's measurement section ends with a chip calibrated: a chip with a layer gain, bias
    offsets and weight errors (the catalogue's per-device effects), read with taps."""
    # private: the demo's calibration section alone; `gift demo` runs every section
    from gift_theory.cli._demo_parts import calibrate_part
    c = calibrate_part("teacher", "4-8-2", 0.05, budget=20)
    assert c["accepted"] and c["accuracy_ideal"] - c["accuracy_before"] > 0.02, c
    assert c["recovered"] > 0.8, c
    assert c["evaluations"] <= 20 and "layer_gain" in c["chip"]


@pytest.mark.slow
def test_noise_physics_reads_a_signal_dependent_noise_through_a_fixed_map():
    """Shot noise on top of awgn: awgn at the shots' level fails the lab's test, and the diagnosis
    names the shot noise (an effect of the input-dependent class)."""
    from gift_theory.calibration import noise_physics
    from gift_theory.lab import simulate_measurement

    params = TEACHER.params()
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(3), (64, 4), minval=-1.0, maxval=1.0))
    shot = gt.Physics.parse(["shot=0.05"], s=0.03)
    meas = simulate_measurement(jax.random.PRNGKey(4), params, x, shot, shots=24, taps=True)
    physics, info = noise_physics(jax.random.PRNGKey(5), meas, s=0.03)  # awgn at 0.03 fails: the diagnosis runs
    assert info["baseline_p"] < 0.01 and info["used"] == "the diagnosis' model", info
    assert set(physics.names) & {"shot", "multiplicative"}, info
