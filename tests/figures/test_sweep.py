"""The sweep engine: labelled arrays, resumability (including a hard kill), failures, Dask."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from paper_figures import Sweep, assemble, load_points, open_dataset, point_id, run_sweep

TOY = "paper_figures._sweep:toy_job"


def toy_sweep(name="toy", **fixed):
    return Sweep(name, {"a": (1, 2, 3), "b": (0.5, 2.0), "kind": ("x", "y")}, TOY, fixed)


def check_values(ds):
    a = ds["a"].values[:, None, None]
    b = ds["b"].values[None, :, None]
    np.testing.assert_array_equal(ds["prod"].values, np.broadcast_to(a * b, ds["prod"].shape))
    np.testing.assert_array_equal(ds["sum"].values, np.broadcast_to(a + b, ds["sum"].shape))


def test_grid_lands_as_labelled_arrays_and_netcdf(tmp_path):
    sw = toy_sweep()
    ds = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False)
    assert dict(ds.sizes) == {"a": 3, "b": 2, "kind": 2}
    assert list(ds["kind"].values) == ["x", "y"]
    assert bool(ds["done"].all()) and ds.attrs["points_done"] == sw.size == 12
    check_values(ds)
    back = open_dataset(os.path.join(tmp_path, "toy.nc"))
    check_values(back)
    assert list(back["kind"].values) == ["x", "y"]
    assert "label" not in ds  # non-numeric results stay in the point files only


def test_point_identity_depends_on_point_and_fixed_options():
    sw, sw2 = toy_sweep(), toy_sweep(seconds=0.0)
    p = sw.points()[3]
    assert point_id(sw, p) == point_id(toy_sweep(), dict(p))
    assert point_id(sw, p) != point_id(sw2, p)
    assert len({point_id(sw, q) for q in sw.points()}) == sw.size


def test_bad_grids_are_rejected():
    with pytest.raises(ValueError, match="repeats"):
        Sweep("s", {"a": (1, 1)}, TOY)
    with pytest.raises(ValueError, match="no values"):
        Sweep("s", {"a": ()}, TOY)
    with pytest.raises(ValueError, match="module:function"):
        Sweep("s", {"a": (1,)}, "toy_job")


def test_resume_runs_only_the_missing_points(tmp_path):
    sw = toy_sweep()
    part = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False, max_new=5)
    assert part.attrs["points_done"] == 5 and int(part["done"].sum()) == 5
    assert int(np.isnan(part["prod"].values).sum()) == 7
    first = load_points(str(tmp_path), sw)
    ds = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False)
    check_values(ds)
    after = load_points(str(tmp_path), sw)
    assert len(after) == sw.size
    for pid, rec in first.items():  # finished points are never recomputed
        assert after[pid]["finished"] == rec["finished"]


def test_failing_points_stay_missing_and_are_retried(tmp_path):
    flag = tmp_path / "fail"
    flag.write_text("")
    sw = toy_sweep(fail_on=2, fail_flag=str(flag))
    ds = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False)
    assert ds.attrs["failed"] == 4
    assert not bool(ds["done"].sel(a=2).any()) and bool(ds["done"].sel(a=[1, 3]).all())
    assert np.isnan(ds["prod"].sel(a=2).values).all()
    flag.unlink()
    ds = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False)
    assert ds.attrs["failed"] == 0
    check_values(ds)


def test_killed_sweep_continues_where_it_stopped(tmp_path):
    """SIGKILL a running sweep, check every persisted point is whole, restart, finish."""
    folder = str(tmp_path)
    sw = Sweep("slow", {"a": tuple(range(8)), "b": (1.0, 3.0)}, TOY, {"seconds": 0.15})
    code = textwrap.dedent(f"""
        from paper_figures import Sweep, run_sweep
        sw = Sweep("slow", {{"a": tuple(range(8)), "b": (1.0, 3.0)}}, {TOY!r}, {{"seconds": 0.15}})
        run_sweep(sw, {folder!r}, scheduler="synchronous", progress=False)
    """)
    log = tmp_path / "stderr.txt"
    with open(log, "wb") as err:
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=err)
    pdir = os.path.join(folder, "slow", "points")
    deadline = time.time() + 60
    try:
        while time.time() < deadline:
            if os.path.isdir(pdir) and len([f for f in os.listdir(pdir) if f.endswith(".json")]) >= 4:
                break
            if proc.poll() is not None:
                pytest.fail(f"sweep ended before it was killed: {log.read_text()[-500:]}")
            time.sleep(0.05)
        else:
            pytest.fail("sweep made no progress in 60 s")
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    done = [f for f in os.listdir(pdir) if f.endswith(".json")]
    assert 4 <= len(done) < sw.size
    for f in done:  # every persisted point is complete JSON with its result
        with open(os.path.join(pdir, f)) as fh:
            rec = json.load(fh)
        assert rec["result"]["prod"] == rec["point"]["a"] * rec["point"]["b"]
    assert not os.path.exists(os.path.join(folder, "slow.nc"))
    before = load_points(folder, sw)
    ds = run_sweep(sw, folder, scheduler="synchronous", progress=False)
    assert bool(ds["done"].all())
    np.testing.assert_array_equal(ds["prod"].values, ds["a"].values[:, None] * ds["b"].values[None, :])
    after = load_points(folder, sw)
    assert all(after[pid]["finished"] == rec["finished"] for pid, rec in before.items())
    assert len([f for f in os.listdir(pdir) if f.startswith(".tmp-")]) <= 1  # at most the one being written at the kill


@pytest.mark.slow
def test_local_dask_cluster_runs_the_same_sweep(tmp_path):
    sw = Sweep("dask", {"a": (1, 2, 3), "b": (2.0,)}, TOY)
    ds = run_sweep(sw, str(tmp_path), n_workers=1, progress=False)
    check_values(ds.expand_dims(kind=["x"], axis=2))
    assert ds["pid"].values[0, 0] != os.getpid()  # ran in a worker process
    again = assemble(str(tmp_path), sw)
    check_values(again.expand_dims(kind=["x"], axis=2))


def test_a_sub_grid_has_the_full_grids_point_ids_and_resumes_into_it(tmp_path):
    """A run in pieces: the points of a restricted sweep are the full sweep's, so the full run
    only adds the rest."""
    from paper_figures._sweep import restrict

    sw = toy_sweep()
    sub = restrict(sw, a=(2, 7), kind=("y",))
    assert sub.dims["a"] == (2,) and sub.dims["kind"] == ("y",) and sub.size == 2
    assert restrict(sw, a=(7,)) is None
    run_sweep(sub, str(tmp_path), scheduler="synchronous", progress=False, save=False)
    assert not os.path.exists(tmp_path / "toy.nc")
    assert set(load_points(str(tmp_path), sw)) == {point_id(sw, p) for p in sub.points()}
    ds = run_sweep(sw, str(tmp_path), scheduler="synchronous", progress=False)
    assert ds.attrs["points_done"] == sw.size
    check_values(ds)


def test_build_by_cells_runs_those_cells_only_and_assembles_what_landed(tmp_path, monkeypatch):
    import paper_figures
    from paper_figures import _jobs, build
    from paper_figures._build import main

    calls = []
    monkeypatch.setattr(_jobs, "_run_ceiling", lambda: lambda **kw: calls.append((kw["s0"], kw["st"], kw["seed"]))
                        or {"loss_before": 1.0, "pathwise_loss": 0.9})
    monkeypatch.setattr(paper_figures._build, "unavailable", lambda job, fixed=None: None)
    res = build("tiny", only="ceiling", cells=[(0.1, 0.3), (0.5, 0.5)], scheduler="synchronous",
                data_dir=str(tmp_path), progress=False)
    assert calls == [(0.1, 0.3, 0)] and res["figures"] == []  # 0.3 is an extended st: the deeper net only
    ds = open_dataset(os.path.join(tmp_path, "ceiling_deep.nc"))
    assert ds.attrs["points_done"] == 1 and ds.attrs["points_total"] == 2
    assert float(ds["pathwise_loss"].sel(s0=0.1, st=0.3, seed=0)) == 0.9
    assert np.isnan(float(ds["pathwise_loss"].sel(s0=0.1, st=0.2, seed=0)))
    assert main(["--scale", "tiny", "--cells", "0.1-0.2", "--draw-only"]) == 2


def test_a_results_own_seconds_does_not_replace_the_jobs(tmp_path, monkeypatch):
    """A job whose result has its own "seconds" (a method's time): the sweep keeps the job's wall
    time as ``seconds`` and the result's as ``result_seconds``."""
    (tmp_path / "timed_job.py").write_text("import time\n\ndef job(a, **_):\n    time.sleep(0.01)\n"
                                           "    return {'seconds': -1.0 * a, 'done': 7.0, 'v': a}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    sw = Sweep("timed", {"a": (1, 2)}, "timed_job:job")
    ds = run_sweep(sw, str(tmp_path / "out"), scheduler="synchronous", progress=False)
    np.testing.assert_array_equal(ds["result_seconds"].values, [-1.0, -2.0])
    np.testing.assert_array_equal(ds["result_done"].values, [7.0, 7.0])
    assert (ds["seconds"].values >= 0.01).all() and ds["done"].values.all()


def test_figures_data_default_outside_an_installed_package(tmp_path, monkeypatch):
    import paper_figures._build as build

    assert build.default_root() == build.HERE  # this source checkout: the repository's folders
    monkeypatch.setattr(build, "HERE", str(tmp_path / "site-packages" / "paper_figures"))
    monkeypatch.chdir(tmp_path)
    assert build.default_root() == str(tmp_path / "gift_figures")
