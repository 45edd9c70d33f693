"""Measurement files: round trips, and every malformed file is one line and exit status 2."""

import os

import jax
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.cli import main
from gift_theory.lab import (Measurement, load_measurement, save_csv, save_measurement, simulate_measurement,
                             validate_arrays)

ARCH = gt.Architecture((3, 5, 2))


@pytest.fixture(scope="module")
def meas():
    params = gt.init_params(jax.random.PRNGKey(0), ARCH)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (6, 3)))
    return simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1), shots=4, taps=True,
                                times=True)


def _same(a: Measurement, b: Measurement):
    np.testing.assert_allclose(a.x, b.x, rtol=1e-7)
    np.testing.assert_allclose(a.y, b.y, rtol=1e-7)
    for p, q in zip(a.params, b.params):
        np.testing.assert_allclose(p.W, q.W, rtol=1e-7)
        np.testing.assert_allclose(p.b, q.b, rtol=1e-7)
    assert (a.taps is None) == (b.taps is None)
    if a.taps is not None:
        for p, q in zip(a.taps, b.taps):
            np.testing.assert_allclose(p, q, rtol=1e-7)
    np.testing.assert_allclose(a.t, b.t, rtol=1e-7)
    assert a.activation == b.activation


def test_shapes_and_times(meas):
    assert meas.y.shape == (6, 4, 2) and meas.taps[0].shape == (6, 4, 5) and meas.t.shape == (6, 4)
    # every shot has its own time; shots of one input are consecutive
    assert len(np.unique(meas.t)) == 24 and np.all(np.diff(meas.t, axis=1) > 0)
    assert meas.t.min() == 0 and meas.t.max() == 1


def test_npz_round_trip(meas, tmp_path):
    path = tmp_path / "m.npz"
    save_measurement(path, meas)
    _same(meas, load_measurement(path))
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".tmp-")]


def test_csv_round_trip(meas, tmp_path):
    path = tmp_path / "m.csv"
    save_csv(path, meas)
    w = tmp_path / "w.npz"
    np.savez(w, **{k: v for k, v in meas.arrays().items() if k[0] in "Wb"})
    _same(meas, load_measurement(path, weights=w))


def test_extra_keys_are_ignored(meas):
    arrays = dict(meas.arrays())
    arrays["notes"] = np.array("bench 3")
    _same(meas, validate_arrays(arrays))


def _broken(meas):
    a = meas.arrays()
    cases = {
        "missing key": ({k: v for k, v in a.items() if k != "y"}, "missing key 'y'"),
        "y rank": ({**a, "y": a["y"][:, 0]}, "y has shape"),
        "nan": ({**a, "y": np.where(np.arange(2) == 0, np.nan, a["y"])}, "NaN or Inf"),
        "inf in weights": ({**a, "W2": np.full_like(a["W2"], np.inf)}, "NaN or Inf"),
        "W does not chain": ({**a, "W2": np.ones((2, 4))}, "W2 has shape"),
        "W1 vs x": ({**a, "W1": np.ones((5, 4))}, "W1 has shape"),
        "b shape": ({**a, "b1": np.ones(4)}, "b1 has shape"),
        "y vs W": ({**a, "y": np.ones((6, 4, 3))}, "outputs per shot"),
        "tap shape": ({**a, "a1": a["a1"][:, :3]}, "tap a1 has shape"),
        "tap of output": ({**a, "a2": a["y"]}, "does not name a hidden layer"),
        "t shape": ({**a, "t": a["t"][:, :2]}, "t has shape"),
        "t range": ({**a, "t": a["t"] + 1.5}, "outside [0, 1]"),
        "one shot": ({**a, "y": a["y"][:, :1], "a1": a["a1"][:, :1], "t": a["t"][:, :1]}, "at least 2"),
        "activation": ({**a, "activation": np.array("relu")}, "unknown activation"),
        "string data": ({**a, "x": np.array([["a"] * 3] * 6)}, "dtype"),
        "b without W": ({**a, "b3": np.ones(2)}, "b3 but no W3"),
    }
    return cases


@pytest.mark.parametrize("case", ([
    "missing key", "y rank", "nan", "inf in weights", "W does not chain", "W1 vs x", "b shape", "y vs W",
    "tap shape", "tap of output", "t shape", "t range", "one shot", "activation", "string data", "b without W"]))
def test_malformed_file_one_line_exit_2(meas, tmp_path, capsys, case):
    arrays, needle = _broken(meas)[case]
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(gt.GiftInputError, match="bad.npz") as err:
        load_measurement(path)
    assert needle in str(err.value) and "\n" not in str(err.value)
    assert main(["diagnose", str(path), "--json"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and len(out.err.strip().splitlines()) == 1 and "Traceback" not in out.err


def test_not_an_npz(tmp_path, capsys):
    path = tmp_path / "junk.npz"
    path.write_bytes(b"not a zip file")
    assert main(["fit", str(path), "--add", "shot", "--json"]) == 2
    err = capsys.readouterr().err
    assert "junk.npz: not an .npz file (an .npz is a zip archive" in err and "pickle" not in err
    assert main(["compare", str(tmp_path / "missing.npz"), "--json"]) == 2


def test_csv_missing_values(meas, tmp_path):
    path = tmp_path / "m.csv"
    save_csv(path, meas)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-1]) + "\n")  # drop one output value
    w = tmp_path / "w.npz"
    np.savez(w, **{k: v for k, v in meas.arrays().items() if k[0] in "Wb"})
    with pytest.raises(gt.GiftInputError, match=r"m.csv: layer 2: input 5 shot 3 misses neuron 2"):
        load_measurement(path, weights=w)
    with pytest.raises(gt.GiftInputError, match="--weights"):
        load_measurement(path)


def test_simulate_command(tmp_path, capsys):
    out = tmp_path / "chip.npz"
    assert main(["simulate", "--arch", "3-5-2", "--inputs", "7", "--shots", "3", "--effect", "awgn=0.05",
                 "--effect", "shot=0.01", "--taps", "--times", "--out", str(out), "--json"]) == 0
    import json
    res = json.loads(capsys.readouterr().out)
    assert res["effects"] == ["awgn", "shot"] and res["params"] == {"s": 0.05, "q": 0.01}
    m = load_measurement(out)
    assert m.y.shape == (7, 3, 2) and m.taps[0].shape == (7, 3, 5) and m.t.shape == (7, 3)
    # same seed, same file
    out2 = tmp_path / "chip2.npz"
    main(["simulate", "--arch", "3-5-2", "--inputs", "7", "--shots", "3", "--effect", "awgn=0.05",
          "--effect", "shot=0.01", "--taps", "--times", "--out", str(out2), "--json"])
    np.testing.assert_array_equal(load_measurement(out2).y, m.y)


def test_simulate_bad_input_writes_nothing(tmp_path, capsys):
    out = tmp_path / "chip.npz"
    out.write_bytes(b"old")
    for argv in (["--arch", "3-x-2"], ["--arch", "3-5-2", "--effect", "bogus=1"], ["--arch", "3-5-2", "--shots", "1"],
                 ["--arch", "3-5-2", "--effect", "shot=-1"]):
        assert main(["simulate", *argv, "--out", str(out), "--json"]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert out.read_bytes() == b"old"
    assert main(["simulate", "--arch", "3-5-2", "--out", str(tmp_path / "nofolder" / "x.npz")]) == 2
