"""The files labs keep (CONTRACTS §3): wide CSV and netCDF / HDF5 beside .npz, read by every
measurement command; round trips exact; bad rows named; nothing half-written."""

import json
import os
import tempfile

import jax
import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gift_theory as gt
from gift_theory.cli import main
from gift_theory.lab import Measurement, load_measurement, save_measurement, simulate_measurement
from gift_theory.lab import detect_format, save_file, save_netcdf, save_wide_csv

def save_weights(path, meas):
    """The weights file beside a CSV (reference §3): the programmed W{l}, b{l} and the activation."""
    np.savez(path, **{k: v for k, v in meas.arrays().items() if k[:1] in "Wb" or k == "activation"})


#: every float64 that float32 -- the precision gift computes in -- holds as a finite number
finite = st.floats(-float(np.finfo(np.float32).max), float(np.finfo(np.float32).max), width=64)


@st.composite
def measurements(draw):
    """Any valid campaign of 1-3 layers, widths 1-3, 1-4 inputs, 2-4 shots, with or without taps
    and times, floats of any finite magnitude (subnormals included)."""
    L = draw(st.integers(1, 3))
    widths = draw(st.lists(st.integers(1, 3), min_size=L + 1, max_size=L + 1))
    n, r = draw(st.integers(1, 4)), draw(st.integers(2, 4))

    def arr(*shape, elements=finite):
        flat = draw(st.lists(elements, min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
        return np.array(flat, np.float64).reshape(shape)

    params = tuple(gt.Layer(arr(widths[l + 1], widths[l]), arr(widths[l + 1])) for l in range(L))
    taps = (tuple(arr(n, r, widths[l]) for l in range(1, L)) if L > 1 and draw(st.booleans()) else None)
    t = arr(n, r, elements=st.floats(0.0, 1.0)) if draw(st.booleans()) else None
    return Measurement(x=arr(n, widths[0]), y=arr(n, r, widths[-1]), params=params, taps=taps, t=t,
                       activation=draw(st.sampled_from(sorted(gt.ACTIVATIONS))))


def _identical(a: Measurement, b: Measurement):
    A, B = a.arrays(), b.arrays()
    assert sorted(A) == sorted(B)
    for k in A:
        assert np.asarray(A[k]).dtype == np.asarray(B[k]).dtype, k
        np.testing.assert_array_equal(A[k], B[k], err_msg=k)  # exact, not close


@pytest.mark.slow
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(measurements())
def test_round_trips_are_exact(meas):
    with tempfile.TemporaryDirectory() as d:
        p_npz, p_nc, p_csv, p_w = (os.path.join(d, f) for f in ("m.npz", "m.nc", "m.csv", "w.npz"))
        save_measurement(p_npz, meas)
        m1 = load_measurement(p_npz)
        save_netcdf(p_nc, m1)
        m2 = load_measurement(p_nc)
        save_wide_csv(p_csv, m2)
        save_weights(p_w, m2)
        m3 = load_measurement(p_csv, weights=p_w)
        m4 = Measurement.from_xarray(m3.to_xarray())
        for m in (m1, m2, m3, m4):
            _identical(meas, m)
        assert [detect_format(p) for p in (p_npz, p_nc, p_csv)] == ["npz", "netcdf", "csv-wide"]
        assert sorted(os.listdir(d)) == ["m.csv", "m.nc", "m.npz", "w.npz"]  # no temp file left


@pytest.fixture(scope="module")
def meas():
    arch = gt.Architecture((3, 5, 2))
    params = gt.init_params(jax.random.PRNGKey(0), arch)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (6, 3)), np.float64)
    return simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1), shots=4, taps=True,
                                times=True)


def test_xarray_names_and_free_dimensions(meas, tmp_path):
    ds = meas.to_xarray()
    assert ds["x"].dims == ("input", "d0") and ds["y"].dims == ("input", "shot", "d2")
    assert ds["a1"].dims == ("input", "shot", "d1") and ds["t"].dims == ("input", "shot")
    assert ds.attrs["activation"] == "tanh"
    # a lab's own names for the other dimensions, shots stored before inputs, no weights in the file
    lab = xr.Dataset({"x": (("input", "pixel"), meas.x),
                      "y": (("shot", "input", "detector"), meas.y.transpose(1, 0, 2)),
                      "a1": (("input", "shot", "hidden"), meas.taps[0]),
                      "t": (("shot", "input"), meas.t.T), "temperature": (("input",), np.ones(meas.n))},
                     attrs={"activation": "tanh"})
    path = tmp_path / "lab.nc"
    lab.to_netcdf(path, engine="h5netcdf")
    save_weights(tmp_path / "w.npz", meas)
    _identical(meas, load_measurement(path, weights=tmp_path / "w.npz"))
    with pytest.raises(gt.GiftInputError, match="lab.nc: holds no weights"):
        load_measurement(path)
    _identical(meas, Measurement.from_xarray(lab, weights=tmp_path / "w.npz"))


def test_plain_hdf5_and_netcdf3(meas, tmp_path):
    import h5py

    path = tmp_path / "plain.h5"
    with h5py.File(path, "w") as f:  # no dimension names at all: read in the order stored
        for k, v in meas.arrays().items():
            if k != "activation":
                f[k] = v
        f.attrs["activation"] = "tanh"
    _identical(meas, load_measurement(path))
    path3 = tmp_path / "classic.nc"
    meas.to_xarray().to_netcdf(path3, engine="scipy")
    assert detect_format(path3) == "netcdf3"
    _identical(meas, load_measurement(path3))


def _wide(meas, tmp_path):
    path = tmp_path / "wide.csv"
    save_wide_csv(path, meas)
    save_weights(tmp_path / "w.npz", meas)
    return path, path.read_text().splitlines()


def test_wide_csv_any_column_order_and_row_order(meas, tmp_path):
    path, lines = _wide(meas, tmp_path)
    rows = [l.split(",") for l in lines]
    perm = np.random.default_rng(0).permutation(len(rows[0]))
    order = [0] + list(1 + np.random.default_rng(1).permutation(len(rows) - 1))
    # columns and rows shuffled, 1-based input and shot ids, an extra column a lab keeps
    shuffled = []
    for i in order:
        row = list(rows[i])
        if i > 0:
            row[0], row[1] = str(int(row[0]) + 1), str(int(row[1]) + 1)
        shuffled.append(",".join([row[j] for j in perm] + ["operator" if i == 0 else "ann"]))
    path.write_text("\n".join(shuffled) + "\n")
    _identical(meas, load_measurement(path, weights=tmp_path / "w.npz"))


def _bad_wide(lines):
    head, body = lines[0], lines[1:]
    cols = head.split(",")
    j_x2 = cols.index("x2")

    def edit(k, col, value):
        rows = [l.split(",") for l in body]
        rows[k][col] = value
        return [head] + [",".join(r) for r in rows]

    return {
        "x disagrees": (edit(5, j_x2, "0.123"), "input 1: x2 differs between its shots"),
        "missing shot": ([head] + body[:6] + body[7:], "input 1 misses shot 2"),
        "missing input": ([head] + body[:4] + body[8:], "input 1 has no rows"),
        "duplicate row": ([head] + body + [body[3]], "input 0 shot 3 appears twice"),
        "not a number": (edit(9, cols.index("y2"), "abc"), "line 11 (input 2): column y2 is not a finite number"),
        "empty cell": (edit(2, cols.index("a1_4"), ""), "line 4 (input 0): column a1_4 is empty"),
        "missing column": ([",".join(c if c != "y1" else "note" for c in cols)] + body, "has column y2 but not y1"),
        "shot not integer": (edit(0, 1, "0.5"), "column shot must hold integers"),
        "no shot column": ([",".join(c if c != "shot" else "trial" for c in cols)] + body, "missing column 'shot'"),
        "tap width": ([",".join(c if c != "a1_5" else "zz" for c in cols)] + body, "tap a1 has shape"),
    }


@pytest.mark.parametrize("case", ["x disagrees", "missing shot", "missing input", "duplicate row", "not a number",
                                  "empty cell", "missing column", "shot not integer", "no shot column", "tap width"])
def test_bad_wide_csv_one_line_exit_2_nothing_written(meas, tmp_path, capsys, case):
    path, lines = _wide(meas, tmp_path)
    text, needle = _bad_wide(lines)[case]
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(gt.GiftInputError) as err:
        load_measurement(path, weights=tmp_path / "w.npz")
    assert needle in str(err.value) and "wide.csv" in str(err.value) and "\n" not in str(err.value)
    out = tmp_path / "out.nc"
    out.write_bytes(b"old")
    assert main(["import", str(path), "--weights", str(tmp_path / "w.npz"), "--out", str(out), "--json"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and len(cap.err.strip().splitlines()) == 1 and "Traceback" not in cap.err
    assert out.read_bytes() == b"old"
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".tmp-")]


def test_import_export_command(meas, tmp_path, capsys):
    src = tmp_path / "m.npz"
    save_measurement(src, meas)
    assert main(["import", str(src), "--out", str(tmp_path / "m.nc"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["format_in"] == "npz" and res["format_out"] == "netcdf" and res["taps"] and res["times"]
    assert main(["export", str(tmp_path / "m.nc"), "--out", str(tmp_path / "m.csv"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["format_out"] == "csv-wide" and res["weights_out"] == str(tmp_path / "m.weights.npz")
    assert main(["import", str(tmp_path / "m.csv"), "--weights", res["weights_out"], "--out",
                 str(tmp_path / "back.npz"), "--json"]) == 0
    capsys.readouterr()
    _identical(meas, load_measurement(tmp_path / "back.npz"))
    for argv, needle in ((["--out", str(tmp_path / "x.txt")], "unknown extension"),
                         (["--out", str(tmp_path / "x.nc"), "--long"], "--long"),
                         (["--out", str(tmp_path / "nofolder" / "x.nc")], "does not exist")):
        assert main(["import", str(src), *argv, "--json"]) == 2
        err = capsys.readouterr().err
        assert needle in err and len(err.strip().splitlines()) == 1
    # the weights written beside the CSV are read back without --weights (and said so) ...
    assert main(["import", str(tmp_path / "m.csv"), "--out", str(tmp_path / "y.nc"), "--json"]) == 0
    assert "weights from " + str(tmp_path / "m.weights.npz") in capsys.readouterr().err
    _identical(meas, load_measurement(tmp_path / "y.nc"))
    # ... and a CSV with none beside it still needs --weights
    os.rename(tmp_path / "m.csv", tmp_path / "alone.csv")
    assert main(["import", str(tmp_path / "alone.csv"), "--out", str(tmp_path / "z.nc")]) == 2
    assert "give --weights" in capsys.readouterr().err


@pytest.mark.slow
def test_same_diagnosis_from_every_format(tmp_path, capsys):
    """One campaign as .npz, wide CSV and netCDF: the same ``gift diagnose --json`` (fixed seed)."""
    src = tmp_path / "chip.npz"
    assert main(["simulate", "--arch", "3-4-2", "--inputs", "24", "--shots", "8", "--effect", "awgn=0.05",
                 "--effect", "shot=0.02", "--taps", "--seed", "3", "--out", str(src), "--json"]) == 0
    capsys.readouterr()
    meas = load_measurement(src)
    save_file(tmp_path / "chip.nc", meas)
    wpath = save_file(tmp_path / "chip.csv", meas)
    results = []
    for path, extra in ((src, []), (tmp_path / "chip.csv", ["--weights", wpath]), (tmp_path / "chip.nc", [])):
        assert main(["diagnose", str(path), *extra, "--candidates", "shot", "--quiet", "--seed", "1",
                     "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        out.pop("seconds", None)
        results.append(out)
    assert results[0]["ranking"] and results[0] == results[1] == results[2]


def test_bad_netcdf_one_line_exit_2(meas, tmp_path, capsys):
    good = tmp_path / "good.nc"
    save_netcdf(good, meas)
    cut = tmp_path / "cut.nc"
    cut.write_bytes(good.read_bytes()[:200])  # an HDF5 signature, then nothing readable
    ds = meas.to_xarray()
    no_y = tmp_path / "no_y.nc"
    ds.drop_vars("y").to_netcdf(no_y, engine="h5netcdf")
    odd = tmp_path / "odd.nc"
    ds.assign(y=(("input", "repeat", "d2"), meas.y)).to_netcdf(odd, engine="h5netcdf")
    named = tmp_path / "named.nc"  # a .nc extension on a text file
    named.write_text("x,y\n1,2\n")
    for path, needle in ((cut, "not a readable netCDF / HDF5 file"), (no_y, "missing key 'y'"),
                         (odd, "variable y has dimensions ('input', 'repeat', 'd2'), no 'shot'"),
                         (named, "not a netCDF / HDF5 file")):
        with pytest.raises(gt.GiftInputError) as err:
            load_measurement(path)
        assert needle in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)
        assert main(["compare", str(path), "--json"]) == 2
        cap = capsys.readouterr()
        assert cap.out == "" and len(cap.err.strip().splitlines()) == 1 and "Traceback" not in cap.err
