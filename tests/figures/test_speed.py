"""What keeps the sweep fast and honest: the persistent compilation cache, the same-numbers
check between two runs, and the scope label of a claim's verdict."""

import pytest
import json
import os
import subprocess
import sys

import numpy as np
import xarray as xr

# private: the cache folder's environment rule (use_compilation_cache keeps the folder this process set)
from gift_theory import _xla
from paper_figures import Sweep, run_sweep
from paper_figures.claims import instance
from paper_figures.same_numbers import compare

TOY = "paper_figures._sweep:toy_job"


def test_compilation_cache_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("GIFT_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("GIFT_CACHE_DIR", str(tmp_path))
    assert _xla.compilation_cache_dir() == os.path.join(str(tmp_path), "xla")
    monkeypatch.setenv("GIFT_COMPILATION_CACHE", str(tmp_path / "elsewhere"))
    assert _xla.compilation_cache_dir() == str(tmp_path / "elsewhere")
    for off in ("off", "0", "none"):
        monkeypatch.setenv("GIFT_COMPILATION_CACHE", off)
        assert _xla.compilation_cache_dir() is None


CHILD = """
import jax, jax.numpy as jnp
from jax import monitoring
hits = []
monitoring.register_event_listener(lambda name, **kw: hits.append(name) if name.endswith("cache_hits") else None)
import gift_theory as gt
gt.use_compilation_cache()  # the explicit opt-in (importing gift_theory changes no setting)
# private: the shared compiled sampler, the program every estimator and the referee reload
from gift_theory._model import compiled_draws
arch = gt.Architecture((64, 48, 32, 10))
jax.block_until_ready(compiled_draws(jax.random.PRNGKey(0), gt.awgn(0.1), arch=arch, shape=(64, 8), dtype=jnp.float32))
print(jax.config.jax_compilation_cache_dir, len(hits))
"""


@pytest.mark.slow
def test_a_second_process_loads_the_compiled_sampler_from_disk(tmp_path):
    env = dict(os.environ, GIFT_COMPILATION_CACHE=str(tmp_path / "xla"))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    runs = [subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=300)
            for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr[-2000:]
    (folder, hits0), (_, hits1) = (r.stdout.split() for r in runs)
    assert folder == str(tmp_path / "xla") and os.listdir(folder)  # the first process wrote its programs
    assert int(hits0) == 0 and int(hits1) >= 1  # the second one read them back instead of compiling


def test_same_numbers_matches_points_and_reports_what_changed(tmp_path):
    sw = Sweep("toy", {"a": (1, 2, 3), "b": (0.5, 2.0)}, TOY)
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    for d in (a, b):
        run_sweep(sw, d, scheduler="synchronous", progress=False)
    same = compare(a, b)["toy"]
    assert same["matched"] == 6 and same["keys"]["prod"]["max_abs"] == 0 and same["keys"]["prod"]["changed"] == 0
    # change one point's result in the second run, with a standard error beside it
    pdir = os.path.join(b, "toy", "points")
    f = sorted(os.listdir(pdir))[0]
    with open(os.path.join(pdir, f)) as fh:
        rec = json.load(fh)
    rec["result"]["prod"] += 0.3
    rec["result"]["prod_se"] = 0.1
    with open(os.path.join(pdir, f), "w") as fh:
        json.dump(rec, fh)
    row = compare(a, b)["toy"]["keys"]["prod"]
    assert row["changed"] == 1 and np.isclose(row["max_abs"], 0.3) and np.isclose(row["max_z"], 3.0)


def _sweep_ds(**fixed):
    ds = xr.Dataset({"x": (("seed",), np.zeros(3))}, coords={"seed": [0, 1, 2]})
    ds.attrs["fixed_json"] = json.dumps(fixed)
    return ds


def test_a_verdict_is_inside_the_papers_scope_only_on_its_nets_and_data():
    paper = instance(_sweep_ds(dataset="mnist5k", net="deep", arch="784-500-250-250-100-50-10", method="gift"),
                     _sweep_ds(dataset="mnist5k", net="shallow", arch="784-500-100-100-10", method="gift"))
    assert paper["scope"] == "inside" and paper["seeds"] == 3
    assert any("seeds" in d for d in paper["differences"]) and any("mnist5k" in d for d in paper["differences"])
    quick = instance(_sweep_ds(dataset="digits", net="deep", arch="64-48-32-32-16-10", method="gift"))
    assert quick["scope"] == "outside"
    other_net = instance(_sweep_ds(dataset="mnist5k", net="deep", arch="784-100-10", method="gift"))
    assert other_net["scope"] == "outside"
