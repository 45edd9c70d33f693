"""A cache only saves time (issue 45): the memo holds data, never code -- a planted pickle is not
read, a tampered entry is computed again; a folder that cannot be written costs the reuse, not
the result (one warning line); a truncated trained-weights entry is trained again.

Private names on purpose: the memo (``_memo``) and its warning registry (``_cachedir``) have no
public API; that a planted or tampered entry is never trusted is a safety contract no public
result shows (a safe and an unsafe cache give the same numbers)."""

import io
import os
import pickle

import jax
import numpy as np
import pytest

from gift_theory import _cachedir, _memo
from gift_theory import Layer


@pytest.fixture
def memo_dir(tmp_path):
    _memo.clear()
    _memo.use_folder(str(tmp_path))
    _cachedir._WARNED.clear()
    yield tmp_path
    _memo.use_folder(None)
    _memo.clear()
    _cachedir._WARNED.clear()


class _Bomb:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_a_planted_pickle_never_runs(memo_dir):
    marker = str(memo_dir / "RAN")
    key = _memo._key("t", (1, 2))
    with open(memo_dir / (key + ".pkl"), "wb") as fh:  # the old format, where it would have been read
        pickle.dump(_Bomb(marker), fh)
    # an .npz of the right name holding a pickled object array
    buf = io.BytesIO()
    np.savez(buf, __key__=np.array(key), __skeleton__=np.array('{"array": 0}'), __digest__=np.array("x"),
             a0=np.array([_Bomb(marker)], dtype=object))
    (memo_dir / (key + ".npz")).write_bytes(buf.getvalue())
    assert _memo.memoized("t", (1, 2), lambda: 3.5) == 3.5
    assert not os.path.exists(marker)


def test_entries_round_trip_as_data_and_a_tampered_one_is_recomputed(memo_dir, capsys):
    value = ((Layer(jax.numpy.arange(6.0).reshape(2, 3), np.float32([1, 2])),), {"n": 1.5, "k": 3, "s": "x",
                                                                                "none": None, "l": [np.int64(4)]})
    _memo.store("t", (7,), value)
    _memo.clear()
    got = _memo.lookup("t", (7,))
    assert isinstance(got[0][0], Layer) and isinstance(got[0][0].W, jax.Array) and isinstance(got[0][0].b, np.ndarray)
    np.testing.assert_array_equal(got[0][0].W, value[0][0].W)
    assert got[1] == {"n": 1.5, "k": 3, "s": "x", "none": None, "l": [np.int64(4)]}
    # one byte of an array changed: the digest no longer matches, the entry is computed again
    path = memo_dir / (_memo._key("t", (7,)) + ".npz")
    with np.load(path) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["a0"] = arrays["a0"] + 1
    np.savez(path, **arrays)
    _memo.clear()
    assert _memo.lookup("t", (7,)) is None
    assert _memo.memoized("t", (7,), lambda: 2.0) == 2.0
    err = capsys.readouterr().err
    assert err.count("gift: warning:") == 1 and "digest does not match" in err
    with pytest.raises(TypeError, match="cannot be kept as data"):
        _memo.store("t", (8,), object())


def test_an_unwritable_memo_folder_keeps_the_result_with_one_warning(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    _memo.clear()
    _cachedir._WARNED.clear()
    _memo.use_folder(str(blocker / "memo"))
    try:
        assert _memo.memoized("u", (1,), lambda: 4.0) == 4.0
        assert _memo.memoized("u", (2,), lambda: 5.0) == 5.0
        assert _memo.memoized("u", (1,), lambda: -1.0) == 4.0  # kept in this process
    finally:
        _memo.use_folder(None)
        _memo.clear()
    err = capsys.readouterr().err
    assert err.count("gift: warning: cannot write the cache") == 1


@pytest.mark.slow
def test_train_with_a_broken_cache_writes_out_and_a_truncated_entry_is_rebuilt(tmp_path, capsys, monkeypatch):
    from gift_theory.cli import main

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("GIFT_CACHE_DIR", str(blocker / "cache"))
    monkeypatch.setenv("GIFT_COMPILATION_CACHE", "off")
    _cachedir._WARNED.clear()
    args = ["train", "--dataset", "digits", "--arch", "64-6-10", "--epochs", "1", "--json"]
    assert main(args + ["--out", str(tmp_path / "w.npz")]) == 0
    out = capsys.readouterr()
    assert (tmp_path / "w.npz").exists() and '"path": null' in out.out
    assert out.err.count("gift: warning:") == 1
    # a cache that works, then its entry cut in half: trained again, rewritten, one warning
    _cachedir._WARNED.clear()
    monkeypatch.setenv("GIFT_CACHE_DIR", str(tmp_path / "cache"))
    assert main(args) == 0
    path = __import__("json").loads(capsys.readouterr().out)["path"]
    with open(path, "r+b") as fh:
        fh.truncate(os.path.getsize(path) // 2)
    assert main(args) == 0
    out = capsys.readouterr()
    assert '"cached": false' in out.out and "cached weights are unreadable" in out.err
    assert main(args) == 0 and '"cached": true' in capsys.readouterr().out
