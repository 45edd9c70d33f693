"""What a careless or unlucky user's files get (issue 45): values float32 cannot hold, the long
CSV's rules (the wide CSV's, neurons numbered from 1 as docs/reference.md §3 says), files that are
not files, and -- as properties -- random valid campaigns that give the same verdict in every
format, and random corruptions that give exit 2 and one line, never exit 1 or a traceback."""

import os
import random
import re
import subprocess
import sys
import threading
import warnings

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gift_theory as gt
# private: the statistics' finite guard, reached publicly only on an overflowing file (the CLI test below)
from gift_theory._finite import NotFinite
from gift_theory.cli import main
from gift_theory.lab import Model, compare, load_measurement, save_measurement, simulate_measurement
from gift_theory.lab import save_csv, save_netcdf, save_wide_csv

from .test_formats import save_weights
# private: that a statistic never drops a non-finite term, for terms no valid file yields
from gift_theory.lab._qtest import over_inputs, q_test

F32 = float(np.finfo(np.float32).max)


@pytest.fixture(scope="module")
def meas():
    arch = gt.Architecture((3, 4, 2))
    params = gt.init_params(jax.random.PRNGKey(0), arch)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (8, 3)), np.float64)
    return simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1), shots=8, taps=True)


def run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line(err):
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _npz(tmp_path, meas, **changes):
    arrays = {**meas.arrays(), **changes}
    arrays = {k: v for k, v in arrays.items() if v is not None}
    path = tmp_path / "m.npz"
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize("key", ["y", "x", "a1", "W2", "t"])
def test_a_value_float32_cannot_hold_is_a_bad_input_naming_the_key(tmp_path, capsys, meas, key):
    arrays = meas.arrays()
    if key == "t":
        arrays["t"] = np.full(meas.y.shape[:2], 0.5)
    a = np.array(arrays[key], np.float64)
    a.flat[3] = 1e300 if key != "t" else 1e39
    path = _npz(tmp_path, meas, **{**arrays, key: a})
    code, out, err = run(capsys, "compare", path, "--effect", "awgn=0.1", "--json")
    line = one_line(err)
    assert code == 2 and out == "" and f"m.npz: {key} holds" in line and "beyond float32's range" in line
    # the largest float32 itself is a value like any other
    a.flat[3] = F32
    with pytest.raises(gt.GiftInputError, match="t has values outside") if key == "t" else _nothing():
        load_measurement(_npz(tmp_path, meas, **{**arrays, key: a}))


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_an_overflow_in_the_statistics_is_a_failed_run_saying_what(tmp_path, capsys, meas):
    path = _npz(tmp_path, meas, y=meas.y * 1e20)  # finite in float32, its squares are not
    code, out, err = run(capsys, "compare", path, "--effect", "awgn=0.1", "--json", "--power-replicates", "0")
    line = one_line(err)
    assert code == 1 and out == "" and "NotFinite" in line and "layer 2" in line and "float32" in line


def test_a_statistic_never_drops_a_non_finite_term():
    T = np.r_[np.ones(5), np.nan, np.ones(4)]
    with pytest.raises(NotFinite, match="index \\[5\\]"):
        over_inputs(T, "the test")
    with pytest.raises(NotFinite):
        q_test(np.array([[1.0, 2.0], [np.inf, 1.0], [0.5, 0.2], [0.1, 0.3]]))
    assert np.isfinite(over_inputs(np.r_[1.0, 2.0, 0.5, 0.3]))


def test_the_finite_check_of_float32_shots_finds_every_bad_value_and_passes_the_largest_good_ones():
    """Shots are checked by their extremes first (no mask as large as the shots): NaN, +inf,
    -inf and a +inf beside a -inf are found at their index; float32's largest values, whose
    float32 sum overflows, are finite; an empty array has nothing to find."""
    # private: the scan's index of the first bad value, exact where a float32 sum would overflow
    from gift_theory._finite import first_bad

    big = np.full((4, 8, 3), np.finfo(np.float32).max, np.float32)
    with np.errstate(over="ignore"):
        assert not np.isfinite(big.sum())
    assert first_bad(big) is None and first_bad(-big) is None
    for bad in ([np.nan], [np.inf], [-np.inf], [np.inf, -np.inf]):
        a = np.ones((4, 8, 3), np.float32)
        a.flat[[37, 90][:len(bad)]] = bad
        assert first_bad(a) == (1, 4, 1)
    assert first_bad(np.ones(5, np.float64)) is None and first_bad(np.r_[1.0, np.nan]) == (1,)
    assert first_bad(np.ones((0, 3), np.float32)) is None and first_bad(np.r_[2.0, -np.inf]) == (1,)


# ---- the long CSV ------------------------------------------------------------------------------

def _long(tmp_path, meas, edit=None):
    path, w = tmp_path / "m.csv", tmp_path / "w.npz"
    save_csv(path, meas)
    save_weights(w, meas)
    if edit is not None:
        lines = path.read_text().splitlines()
        path.write_text("\n".join(edit(lines)) + "\n")
    return path, w


def test_the_long_csv_numbers_neurons_from_1_as_documented(tmp_path, meas):
    path, w = _long(tmp_path, meas)
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    assert rows[:, 3].min() == 1 and rows[rows[:, 2] == 0, 3].max() == 3  # x1..x3 are neurons 1..3 of layer 0
    got = load_measurement(path, weights=w)
    for k, v in meas.arrays().items():
        np.testing.assert_array_equal(got.arrays()[k], v, err_msg=k)


def test_the_long_csv_follows_the_wide_csvs_rules(tmp_path, capsys, meas):
    head_cols = "input,shot,layer,neuron,value".split(",")

    def x_differs(lines):  # x of input 2 given again on shot 1, another value
        row = next(l for l in lines[1:] if l.startswith("2,0,0,1,"))
        v = row.split(",")
        v[1], v[4] = "1", repr(float(v[4]) + 0.5)
        return lines + [",".join(v)]

    def x_again(lines):  # the same x on another shot: allowed
        row = next(l for l in lines[1:] if l.startswith("2,0,0,1,"))
        return lines + [row.replace("2,0,0,1,", "2,5,0,1,", 1)]

    def neuron0(lines):
        return [lines[0]] + [",".join(l.split(",")[:3] + ["0"] + l.split(",")[4:]) if i == 1 else l
                             for i, l in enumerate(lines[1:], 1)]

    def huge_input(lines):
        v = lines[-1].split(",")
        v[0] = "100000000000"
        return lines + [",".join(v)]

    def gap(lines):  # input 3 has no rows at all
        return [lines[0]] + [l for l in lines[1:] if not l.startswith("3,")]

    cases = {x_differs: "input 2: x1 differs between its rows", neuron0: "column neuron must hold integers >= 1",
             huge_input: "input 100000000000 shot", gap: "input 3 has no rows"}
    for edit, needle in cases.items():
        path, w = _long(tmp_path, meas, edit)
        code, out, err = run(capsys, "compare", path, "--weights", w, "--effect", "awgn=0.1", "--json")
        assert code == 2 and out == "" and needle in one_line(err), (edit.__name__, err)
    path, w = _long(tmp_path, meas, x_again)
    np.testing.assert_array_equal(load_measurement(path, weights=w).x, meas.x)
    assert head_cols


def test_a_header_only_csv_is_one_line_and_no_warning(tmp_path, capsys, meas):
    for name, header in (("long.csv", "input,shot,layer,neuron,value"), ("wide.csv", "input,shot,x1,y1")):
        path = tmp_path / name
        path.write_text(header + "\n")
        save_weights(tmp_path / "w.npz", meas)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            code, out, err = run(capsys, "compare", path, "--weights", tmp_path / "w.npz", "--json")
        assert code == 2 and "no data rows" in one_line(err)


# ---- files that are not files, and the smaller items ------------------------------------------

def test_a_fifo_and_a_device_are_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "m.npz"
    os.mkfifo(fifo)
    done = []
    th = threading.Thread(target=lambda: done.append(run(capsys, "compare", fifo, "--json")), daemon=True)
    th.start()
    th.join(60)
    assert done, "gift compare on a FIFO hangs"
    code, out, err = done[0]
    assert code == 2 and "is a pipe (FIFO), not a file to read" in one_line(err)
    code, out, err = run(capsys, "compare", "/dev/zero", "--json")
    assert code == 2 and "/dev/zero: is a device" in one_line(err)


def test_the_smaller_items(tmp_path, capsys, meas):
    # activation stored as bytes is the string it spells
    path = _npz(tmp_path, meas, activation=np.array(b"tanh"))
    assert load_measurement(path).activation == "tanh"
    # the key that is missing is named
    arrays = meas.arrays()
    del arrays["W2"]
    np.savez(tmp_path / "nw.npz", **arrays)
    with pytest.raises(gt.GiftInputError, match="has b2 but no W2"):
        load_measurement(tmp_path / "nw.npz")
    # a file named .npz that is no zip archive is said to be so (not "pickled data")
    (tmp_path / "junk.npz").write_text("x,y\n1,2\n")
    with pytest.raises(gt.GiftInputError, match="an .npz is a zip archive") as err:
        load_measurement(tmp_path / "junk.npz")
    assert "pickle" not in str(err.value)
    # too few inputs: the file is named
    few = simulate_measurement(jax.random.PRNGKey(3), meas.params, meas.x[:3], gt.Physics.create(s=0.1), shots=8)
    save_measurement(tmp_path / "few.npz", few)
    code, out, err = run(capsys, "diagnose", tmp_path / "few.npz", "--json", "--quiet")
    assert code == 2 and "few.npz: has 3 input(s)" in one_line(err)


# ---- properties: every loader, the same verdict; corruptions, exit 2 ------------------------------

ARCH = gt.Architecture((3, 4, 2))


@st.composite
def campaigns(draw):
    """Valid campaigns of one shape (one compiled program serves every example): 3-4-2, 6 inputs
    x 8 shots, taps and times or not, values drawn around a simulated chip's (any scale)."""
    seed = draw(st.integers(0, 2 ** 16))
    scale = draw(st.sampled_from([1e-6, 1.0, 1e6]))
    taps, times = draw(st.booleans()), draw(st.booleans())
    params = gt.init_params(jax.random.PRNGKey(seed), ARCH)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(seed + 1), (6, 3)), np.float64) * scale
    m = simulate_measurement(jax.random.PRNGKey(seed + 2), params, x, gt.Physics.create(s=0.1), shots=8, taps=taps,
                             times=times)
    return m


def _all_formats(folder, m):
    paths = {"npz": folder / "m.npz", "nc": folder / "m.nc", "wide": folder / "w.csv", "long": folder / "l.csv"}
    save_measurement(paths["npz"], m)
    save_netcdf(paths["nc"], m)
    save_wide_csv(paths["wide"], m)
    save_csv(paths["long"], m)
    save_weights(folder / "weights.npz", m)
    return paths


@pytest.mark.slow
@settings(max_examples=8, deadline=None)
@given(m=campaigns())
def test_every_loader_gives_the_same_campaign_and_verdict(tmp_path_factory, m):
    folder = tmp_path_factory.mktemp("fmt")
    paths = _all_formats(folder, m)
    loaded = {k: load_measurement(p, weights=folder / "weights.npz") for k, p in paths.items()}
    verdicts = {}
    for k, got in loaded.items():
        for key, v in m.arrays().items():
            np.testing.assert_array_equal(got.arrays()[key], v, err_msg=f"{k}: {key}")
        c = compare(jax.random.PRNGKey(0), Model(gt.Physics.create(s=0.1)), got)
        verdicts[k] = (c.discrepancy, c.p_value)
    assert len(set(verdicts.values())) == 1, verdicts


def _corrupt(data: bytes, how: str, rnd: random.Random) -> bytes:
    if how == "truncate":
        return data[: rnd.randrange(len(data))]
    if how == "flip":
        b = bytearray(data)
        for _ in range(rnd.randint(1, 8)):
            i = rnd.randrange(len(b))
            b[i] ^= 1 << rnd.randrange(8)
        return bytes(b)
    if how == "garbage":
        i = rnd.randrange(len(data))
        return data[:i] + bytes(rnd.randrange(256) for _ in range(rnd.randint(1, 40))) + data[i:]
    lines = data.decode("utf-8", "replace").splitlines()
    i = rnd.randrange(1, max(len(lines), 2))
    if how == "drop_line":
        del lines[min(i, len(lines) - 1)]
    elif how == "duplicate_line":
        lines.insert(i, lines[min(i, len(lines) - 1)])
    elif how == "bad_number":
        cells = lines[min(i, len(lines) - 1)].split(",")
        cells[rnd.randrange(len(cells))] = rnd.choice(["nan", "inf", "1e400", "", "abc", "-", "1,2"])
        lines[min(i, len(lines) - 1)] = ",".join(cells)
    elif how == "drop_column":
        j = rnd.randrange(len(lines[0].split(",")))
        lines = [",".join(c for k, c in enumerate(l.split(",")) if k != j) for l in lines]
    return ("\n".join(lines) + "\n").encode()


def _central_field(data: bytes, offset: int, value: int, size: int = 2) -> bytes:
    """``data`` (a zip archive) with a field of every central-directory header set to ``value``
    (little-endian; offsets from the header's signature PK\\x01\\x02)."""
    out = bytearray(data)
    for m in re.finditer(rb"PK\x01\x02", bytes(data)):
        out[m.start() + offset:m.start() + offset + size] = value.to_bytes(size, "little")
    return bytes(out)


@pytest.mark.parametrize("field, offset, value", [("version needed", 6, 109), ("flags: encrypted", 8, 1),
                                                  ("compression method", 10, 99)])
def test_an_archive_zipfile_cannot_open_is_a_bad_input(tmp_path, capsys, meas, field, offset, value):
    """A header zipfile refuses with NotImplementedError (a version or compression method it does
    not know) or RuntimeError (an encrypted member) is a damaged .npz, exit 2 in one line -- for a
    measurement and for the weights beside it; the file is left as it was."""
    path = _npz(tmp_path, meas)
    weights = tmp_path / "weights.npz"
    save_weights(weights, meas)
    for bad in (path, weights):
        good = bad.read_bytes()
        bad.write_bytes(_central_field(good, offset, value))
        before = bad.read_bytes()
        code, out, err = run(capsys, "compare", path, "--weights", weights, "--effect", "awgn=0.1", "--json",
                             "--power-replicates", "0")
        assert code == 2 and out == "", (field, code, err)
        assert one_line(err).startswith(f"{bad}: not a readable .npz"), (field, err)
        assert bad.read_bytes() == before
        bad.write_bytes(good)


def _heap_objects(data: bytes):
    """(collection start, collection end, [(object start, index, size)]) of the first HDF5 global
    heap collection in ``data``, read by the file format's layout (not by gift's walk)."""
    at = data.index(b"GCOL\x01\x00\x00\x00")
    end = at + int.from_bytes(data[at + 8:at + 16], "little")
    objects, p = [], at + 16
    while p + 16 <= end:
        index, size = int.from_bytes(data[p:p + 2], "little"), int.from_bytes(data[p + 8:p + 16], "little")
        objects.append((p, index, size))
        p += size if index == 0 else 16 + -(-size // 8) * 8
    return at, end, objects


def test_a_damaged_global_heap_in_a_netcdf_file_is_a_bad_input_not_a_hang(tmp_path, capsys, meas):
    """netCDF-4 keeps each variable's dimension list in the HDF5 global heap, which has no checksum.
    A free-space object of size 0 there sends the HDF5 library into an endless loop (found by the
    corruption test below: one bit flipped, 8 -> 10 in an object's size, misaligns the walk onto
    a zero); an object running past its collection makes it read past its buffer. Both, and a
    collection longer than the file, are one line and exit 2, the file left as it was. The hang is
    tried in a child process with a time limit, so that a regression fails instead of hanging."""
    path = tmp_path / "m.nc"
    save_netcdf(path, meas)
    save_weights(tmp_path / "w.npz", meas)
    good = path.read_bytes()
    at, end, objects = _heap_objects(good)
    free = [p for p, index, _ in objects if index == 0]
    first = next(p for p, index, _ in objects if index > 0)
    assert free and objects[-1][1] == 0, objects  # h5netcdf leaves free space at the collection's end

    def with_field(offset, value):
        b = bytearray(good)
        b[offset:offset + 8] = value.to_bytes(8, "little")
        return bytes(b)

    cases = {"free space of size 0": (with_field(free[0] + 8, 0), "does not reach past its own header"),
             "an object past the end": (with_field(first + 8, end - first), "runs past the collection's end"),
             "a collection past the file": (with_field(at + 8, len(good)), "claims")}
    args = ["compare", str(path), "--weights", str(tmp_path / "w.npz"), "--effect", "awgn=0.1", "--json",
            "--power-replicates", "0"]
    for name, (data, says) in cases.items():
        path.write_bytes(data)
        if name == "free space of size 0":
            r = subprocess.run([sys.executable, "-c", "import sys; from gift_theory.cli import main; "
                                "sys.exit(main(sys.argv[1:]))", *args], capture_output=True, text=True, timeout=120)
            code, out, err = r.returncode, r.stdout, r.stderr
        else:
            code, out, err = run(capsys, *args)
        assert code == 2 and out == "", (name, code, err)
        line = one_line(err)
        assert line.startswith(f"{path}: not a readable netCDF / HDF5 file (the global heap collection at byte {at}")
        assert says in line, (name, line)
        assert path.read_bytes() == data
    path.write_bytes(good)
    assert load_measurement(path, weights=tmp_path / "w.npz").y.shape == meas.y.shape


@settings(max_examples=40, deadline=None)
@given(fmt=st.sampled_from(["npz", "nc", "wide", "long"]),
       how=st.sampled_from(["truncate", "flip", "garbage", "drop_line", "duplicate_line", "bad_number", "drop_column"]),
       seed=st.integers(0, 2 ** 31))
@pytest.mark.slow
def test_a_corrupted_file_is_exit_2_and_one_line(tmp_path_factory, capsys, meas, fmt, how, seed):
    """Any corruption of a valid file: either still a valid campaign (exit 0) or a bad input with one
    line on stderr (exit 2); never a traceback, never exit 1."""
    if how in ("drop_line", "duplicate_line", "bad_number", "drop_column") and fmt in ("npz", "nc"):
        how = "flip"
    folder = tmp_path_factory.mktemp("bad")
    path = _all_formats(folder, meas)[fmt]
    path.write_bytes(_corrupt(path.read_bytes(), how, random.Random(seed)))
    code, out, err = run(capsys, "compare", path, "--weights", folder / "weights.npz", "--effect", "awgn=0.1", "--json",
                         "--power-replicates", "0")
    assert code in (0, 2), (code, err)
    if code == 2:
        one_line(err)
        assert out == ""
