"""Every figure script at the tiny scale, drawn from saved data; the claims summary on data whose
truth is known; the paper's noise laws mapped onto CONTRACTS §2; the CLI's bad input."""

import math
import os

import jax
import numpy as np
import pytest

import gift_theory as gt
import paper_figures
from paper_figures import _jobs, build, true_noise
from paper_figures._build import FIGURES

SWEEP_FIGURES = [n for n in FIGURES if n not in ("example_fine_tuning", "bound_region", "error_ladder")]


def fake_run_finetune(dataset, arch, s0, st, true_effects, method, seed, **options):
    """A stand-in chip + GIFT with known improvements: deep nets gain 10 points of % more accuracy
    than shallow ones, test gains = train gains + 1, multiplicative noise loses accuracy; the
    first-order prediction is exact but under multiplicative noise, where the realised change
    has the wrong sign."""
    depth = arch.count("-")
    acc_gain = 20.0 + 40.0 * st + 0.5 * seed - (10.0 if depth < 3 else 0.0)
    loss_gain = 10.0 + 20.0 * st + 0.5 * seed - (5.0 if depth < 3 else 0.0)
    if any(e.startswith("multiplicative") for e in true_effects):
        acc_gain = -5.0 - 0.5 * seed
    out = {"dataset": dataset, "arch": [int(w) for w in arch.split("-")], "method": method, "s0": s0, "st": st,
           "in_situ_evaluations": 5, "seconds": 0.01}
    for p, extra in (("", 0.0), ("test_", 1.0)):
        out[f"{p}loss_before"], out[f"{p}loss_after"] = 0.5, 0.5 * (1 - (loss_gain + extra) / 100)
        out[f"{p}accuracy_before"], out[f"{p}accuracy_after"] = 0.8, 0.8 * (1 + (acc_gain + extra) / 100)
    pred = -(0.01 + 0.1 * st + 0.001 * seed + 0.002 * depth)
    real = -pred if any(e.startswith("multiplicative") for e in true_effects) else pred
    out["info"] = {"accepted": True, "prediction": {
        "predicted_change": pred, "predicted_change_se": 1e-4, "predicted_change_2nd": pred,
        "realised_change": real, "realised_change_se": 1e-4, "s_model": options["predict_s"]}}
    return out


def fake_run_ceiling(dataset, arch, s0, st, true_effects, seed, kinds, train_epochs=None, **options):
    """A stand-in ceiling with known gains: the GIFT (pathwise) line gains 2 % (+3 with a w0
    trained under 30 epochs), the gradient line 1 % (+5 under 30 epochs), the printed line 0.5 %,
    0.1 % more per seed; |cos(pathwise, gradient)| 0.3."""
    short = train_epochs is not None and train_epochs < 30
    gain = {"pathwise": 2.0 + 3.0 * short, "gradient": 1.0 + 5.0 * short, "score_paper": 0.5}
    out = {"dataset": dataset, "arch": [int(w) for w in arch.split("-")], "s0": s0, "st": st,
           "loss_before": 0.5, "accuracy_before": 0.8, "test_loss_before": 0.5, "test_accuracy_before": 0.8}
    for k in kinds:
        g = gain[k] + 0.1 * seed
        out.update({f"{k}_loss": 0.49, f"{k}_test_loss": 0.49, f"{k}_accuracy": 0.8 * (1 + g / 100),
                    f"{k}_test_accuracy": 0.8 * (1 + g / 100), f"{k}_accuracy_best": 0.8 * (1 + g / 100),
                    f"{k}_test_accuracy_at_best": 0.8 * (1 + g / 100), f"{k}_rel_step_loss": 1e-3,
                    f"{k}_rel_step_acc": 1e-3, f"{k}_at_edge": False})
    if "gradient" in kinds:
        out["cos_pathwise_gradient"] = -0.3
        out["cos_score_paper_gradient"] = 0.05
    out["scan"] = {}
    return out


@pytest.fixture
def fake_finetune(monkeypatch):
    monkeypatch.setattr(_jobs, "_run_finetune", lambda: fake_run_finetune)
    monkeypatch.setattr(_jobs, "_run_ceiling", lambda: fake_run_ceiling)
    monkeypatch.setattr(_jobs, "unavailable", lambda job, fixed=None: None)
    monkeypatch.setattr(paper_figures._build, "unavailable", lambda job, fixed=None: None)


@pytest.mark.slow
def test_every_sweep_figure_is_drawn_from_saved_data_and_claims_follow_the_data(tmp_path, fake_finetune,
                                                                                 monkeypatch):
    # the estimator job is exercised for real in test_real_jobs; here a stand-in with the -1/2 law
    monkeypatch.setattr(_jobs, "estimator_job", lambda method, K1, K2, rep, **kw: {
        "rel_error": 3.0 / math.sqrt(K1 * K2), "rel_error_rescaled": 3.0 / math.sqrt(K1 * K2),
        "rel_error_debiased": 3.0 / math.sqrt(K1 * K2), "rel_se": 3.0 / math.sqrt(K1 * K2), "ref_rel_se": 0.01})
    data, figs = str(tmp_path / "data"), str(tmp_path / "fig")
    res = build("tiny", scheduler="synchronous", data_dir=data, figure_dir=figs, progress=False)
    status = {f["name"]: f for f in res["figures"]}
    for name in SWEEP_FIGURES:
        assert status[name]["status"] == "drawn", (name, status[name]["status"])
        path = status[name]["path"]
        with open(path, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    for s in res["sweeps"]:
        assert s["points_done"] == s["points_total"] and s["failed"] == 0
    # issue 25's figure functions take ax= and return that Figure, choosing no backend
    import matplotlib
    import matplotlib.pyplot as plt

    from paper_figures import ceiling, extended, gain_vs_baseline, performance_gift, undertrained
    from paper_figures._sweep import open_dataset

    use = matplotlib.use
    monkeypatch.setattr(matplotlib, "use", lambda *a, **k: pytest.fail("a figure function called matplotlib.use"))
    saved = {n: open_dataset(os.path.join(data, f"{n}.nc")) for n in (
        "gift_awgn_deep", "gift_regime", "variants", "rivals_regime", "ceiling_deep", "ceiling_shallow", "undertrained",
        "undertrained_ceiling", "extended", "ceiling_extended")}
    for mod, shape in ((gain_vs_baseline, (2, 4)), (performance_gift, (1, 2)), (undertrained, (1, 2)),
                       (ceiling, (2, 2)), (extended, (3, 2))):  # extended: gift, gift-noconfirm, the ceiling
        fig, axes = plt.subplots(*shape, figsize=(5 * shape[1], 4.5 * shape[0]))  # room for the decorations
        assert mod.draw(saved, ax=axes if shape[0] > 1 else list(axes)) is fig
        plt.close(fig)
    points = gain_vs_baseline.cell_points(saved["gift_regime"], "train")  # one (s0, st) cell: 20 + 40 * 0.3 + 0.25
    assert len(points) == 1 and points[0]["gain_pct"] == pytest.approx(32.25) and points[0]["baseline"] == 0.8
    assert points[0]["pct_max"] == pytest.approx(32.5) and points[0]["gain_abs"] == pytest.approx(0.8 * 32.25)
    monkeypatch.setattr(matplotlib, "use", use)  # build (the batch driver) chooses agg
    # drawing again from saved data only gives the same figures without running a job
    monkeypatch.setattr(_jobs, "_run_finetune", lambda: pytest.fail("--draw-only ran a job"))
    again = build("tiny", data_dir=data, figure_dir=figs, compute=False, progress=False, only="performance_gift")
    assert again["figures"][0]["status"] == "drawn"

    c = res["claims"]
    acc = c["accuracy_gain_up_to_28pct"]  # our grid's best cell: 20 + 40 * 0.2 + mean(0, 0.5) = 28.25 %
    assert acc["best_cell_mean_pct"] == pytest.approx(28.25, abs=1e-6)
    assert acc["best_cell"] == {"s0": 0.1, "st": 0.2}
    # judged over every cell (the extended one at st = 0.35 is the best: 20 + 14 = 34 % of a 0.8 baseline,
    # 27.2 points) and reading: the relative readings reach 28, the absolute ones do not
    g = acc["readings"]["methods"]["gift"]
    assert g["cells"] == 4 + 1 + 1 and g["runs"] == 8 + 2 + 1
    assert g["mean_relative"]["value"] == pytest.approx(34.0) and g["mean_relative"]["sweep"] == "extended"
    assert g["single_absolute"]["value"] == pytest.approx(27.2) and not g["single_absolute"]["holds"]
    assert acc["holds_under"] == ["mean_relative", "single_relative"]
    assert acc["fails_under"] == ["mean_absolute", "single_absolute"]
    assert acc["verdict"] == "reproduced under some readings"
    assert acc["readings"]["methods"]["gift-noconfirm"]["cells"] == 2  # variants (0.1, 0.2) and extended
    deeper = c["deeper_benefits_more"]
    assert deeper["acc_pct"]["paired_diff_mean"] == pytest.approx(10.0, abs=1e-6)
    assert deeper["verdict"] == "supported"
    assert c["robust_to_non_awgn"]["verdict"] == "contradicted"  # the stand-in loses accuracy under multiplicative
    assert c["robust_to_non_awgn"]["per_noise_kind"]["laplace"]["acc_pct_mean"] > 20
    tr = c["test_resembles_train"]
    assert tr["acc_pct"]["test_minus_train_mean"] == pytest.approx(1.0, abs=1e-6) and tr["verdict"] == "supported"
    diag = c["gains_at_s0_eq_st"]
    assert diag["n"] == 4 and diag["loss_pct_mean"] == pytest.approx(13.25, abs=1e-6)
    assert diag["verdict"] == "supported"
    fo = c["theorem1_first_order"]  # 8 + 8 awgn points exact, 2 of 6 violated ones (multiplicative) of the wrong sign
    assert fo["points"] == 22 and fo["wrong"] == 2 and fo["sign_wrong"] == 2
    assert {p["noise_kind"] for p in fo["wrong_points"]} == {"multiplicative"}
    assert fo["verdict"] == "fails"  # 2/22 > 5 %
    assert all(v["scope"] == "outside" for v in c.values())  # tiny nets on digits: not the paper's instance
    # issue 25: the ceiling (pathwise 2 %, seed 0 only at tiny) and the retrain oracle (the stand-in's
    # 20 + 40 st + 0.5 seed, seeds 0 and 1) at the best cell; the extended st's best cell (0.1, 0.3)
    assert acc["ceiling_pct"] == pytest.approx(2.0, abs=1e-9) and acc["ceiling_n"] == 1
    assert acc["ceiling_printed_test_pct"] == pytest.approx(0.5, abs=1e-9)
    assert acc["retrain_pct"] == pytest.approx(28.25, abs=1e-6) and acc["retrain_n"] == 2
    assert acc["retrain_s0_pct"] == pytest.approx(28.25, abs=1e-6)
    assert acc["regime"]["best_cell"] == {"s0": 0.1, "st": 0.3}
    assert acc["regime"]["best_cell_mean_pct"] == pytest.approx(32.25, abs=1e-6)
    assert acc["regime"]["retrain_pct"] == pytest.approx(32.0, abs=1e-6)  # from rivals_regime (seed 0)
    riv = acc["regime"]["rivals"]  # every in-situ method of rivals_regime there (the oracle is not one)
    from paper_figures._scales import sweeps

    assert set(riv) == set(sweeps("tiny")["rivals_regime"].dims["method"]) - {"retrain"} and "gift" in riv
    assert all(v["pct"] == pytest.approx(32.0, abs=1e-6) and v["chip_evaluations"] == 5 for v in riv.values())
    assert "in situ there: " in acc["summary"]
    assert "ceiling of the GIFT line 2.00" in acc["summary"]
    hi = acc["ceiling_highest"]  # the stand-in's ceiling: 2 % everywhere, one seed: no interval, no verdict on 28 %
    assert hi["mean_pct"] == pytest.approx(2.0, abs=1e-9) and hi["n"] == 1 and hi["reaches_28pct"] is None
    assert "not every cell has an interval" in acc["summary"]
    # under-training: the GIFT line gains 3 % more from the short w0, but the gradient line 1 % more than it
    u = c["undertrained_w0"]
    assert u["ceiling_short_minus_long_pct"]["mean"] == pytest.approx(3.0, abs=1e-9)
    assert u["ceiling_gift_minus_gradient_short_pct"]["mean"] == pytest.approx(-1.0, abs=1e-9)
    assert u["verdict"] == "gradient step" and "rule" in u
    assert u["per_epochs"]["2"]["abs_cos_gift_gradient"]["mean"] == pytest.approx(0.3)
    assert u["per_epochs"]["30"]["abs_cos_printed_gradient"]["mean"] == pytest.approx(0.05)


@pytest.mark.slow
@pytest.mark.parametrize("spread, reaches", [(1.0, False), (30.0, True)])
def test_the_ceiling_over_the_grid_reaches_28pct_only_when_a_cell_s_interval_does(spread, reaches):
    """The grid-wide ceiling of the 28 % claim: the highest cell, and a verdict on 28 % from the
    cells' 95 % upper bounds (a cell at 10 % mean whose seeds spread widely can reach it)."""
    import xarray as xr

    from paper_figures.claims import _ceiling_highest

    rng = np.random.default_rng(0)
    seeds, s0, st = 4, [0.02, 0.1], [0.2, 0.4]
    gain = np.zeros((2, 2, seeds))
    gain[0, 1] = 10.0 + spread * rng.standard_normal(seeds)  # the best cell, (0.02, 0.4)
    gain[1, 0] = 3.0 + 0.1 * rng.standard_normal(seeds)
    before = np.full_like(gain, 0.5)
    after = before * (1 + gain / 100)
    dims, coords = ("s0", "st", "seed"), {"s0": s0, "st": st, "seed": np.arange(seeds)}
    var = {k: (dims, v) for k, v in {
        "loss_before": before + 1, "pathwise_loss": before + 1, "accuracy_before": before,
        "pathwise_accuracy_best": after, "test_loss_before": before + 1, "pathwise_test_loss": before + 1,
        "test_accuracy_before": before, "pathwise_test_accuracy_at_best": after}.items()}
    hi = _ceiling_highest("unused", {"ceiling_deep": xr.Dataset(var, coords=coords)})
    v = gain[0, 1]
    m, h = v.mean(), 3.182446305284263 * v.std(ddof=1) / 2  # t(0.975, 3) s / sqrt(4)
    assert hi["best_cell"] == {"s0": 0.02, "st": 0.4} and hi["cells"] == 4 and hi["n"] == seeds
    assert hi["mean_pct"] == pytest.approx(m) and hi["ci95"] == pytest.approx(h)
    assert hi["highest_upper95_pct"] == pytest.approx(m + h) and hi["reaches_28pct"] is reaches
    assert bool(m + h >= 28) is reaches  # the instance does what its name says
    assert hi["test_pct"] == pytest.approx(m) and hi["baseline_accuracy"] == pytest.approx(0.5)


def _finetune_ds(s0, st, before, gain_pct):
    """A fine-tuning sweep at one (s0, st) cell: per-seed relative accuracy gains on a baseline."""
    import xarray as xr

    gain = np.asarray(gain_pct, float)[None, None, :]
    b = np.full(gain.shape, before)
    dims = ("s0", "st", "seed")
    var = {f"{p}{k}": (dims, v) for p in ("", "test_") for k, v in (
        ("accuracy_before", b), ("accuracy_after", b * (1 + gain / 100)), ("loss_before", b), ("loss_after", b))}
    return xr.Dataset(var, coords={"s0": [s0], "st": [st], "seed": np.arange(gain.size)})


def test_the_28pct_claim_is_judged_over_every_cell_and_reading():
    """Mean over seeds or best single run, relative or absolute: each reading takes its own best cell
    (a high relative gain at a chance baseline is few accuracy points), and the verdict names the
    readings under which 28 holds and those under which it does not."""
    from paper_figures.claims import readings_table, summarise

    loaded = {"gift_awgn_deep": _finetune_ds(0.02, 0.1, 0.6, [15.0, 17.0, 19.0]),  # 9 / 10.2 / 11.4 points
              "gift_regime": _finetune_ds(0.02, 0.8, 0.1, [20.0, 40.0, 30.0])}    # 2 / 4 / 3 points
    acc = summarise("no-such-folder", loaded)["accuracy_gain_up_to_28pct"]
    g = acc["readings"]["methods"]["gift"]
    assert g["cells"] == 2 and g["runs"] == 6 and acc["readings"]["sweeps"] == ["gift_awgn_deep", "gift_regime"]
    assert g["mean_relative"]["value"] == pytest.approx(30.0) and g["mean_relative"]["cell"] == {"s0": 0.02, "st": 0.8}
    assert g["mean_relative"]["ci95"] == pytest.approx(4.302652729911275 * 10.0 / np.sqrt(3))  # t(0.975, 2) sd / sqrt(n)
    assert g["mean_absolute"]["value"] == pytest.approx(10.2) and g["mean_absolute"]["cell"] == {"s0": 0.02, "st": 0.1}
    assert g["single_relative"]["value"] == pytest.approx(40.0) and g["single_relative"]["seed"] == 1
    assert g["single_absolute"]["value"] == pytest.approx(11.4) and g["single_absolute"]["seed"] == 2
    assert acc["holds_under"] == ["mean_relative", "single_relative"]
    assert acc["fails_under"] == ["mean_absolute", "single_absolute"]
    assert acc["verdict"] == "reproduced under some readings"
    assert "28 holds under mean, relative, single run, relative" in acc["summary"]
    # below 28 everywhere: 'not reproduced' unless the best cell's interval lies above 0
    loaded["gift_regime"] = _finetune_ds(0.02, 0.8, 0.1, [20.0, 21.0, 22.0])
    acc = summarise("no-such-folder", loaded)["accuracy_gain_up_to_28pct"]
    assert acc["holds_under"] == [] and acc["verdict"] == "gains, smaller"
    assert "none of the four readings" in acc["summary"]
    assert "| GIFT | 2 / 6 |" in readings_table(acc)


def test_the_rivals_beside_the_regime_are_each_method_s_own_seeds():
    """regime["rivals"]: each in-situ method's gain from its own points (a method whose name is an
    xarray keyword must not select everything), best first, the oracle left out."""
    import xarray as xr

    from paper_figures.claims import _rivals_at

    methods, seeds = ["gift", "pat", "retrain"], 3
    gain = np.array([1.0, 60.0, 90.0])[:, None, None, None] + np.arange(seeds)  # (method, s0, st, seed)
    before = np.full(gain.shape, 0.4)
    dims = ("method", "s0", "st", "seed")
    ds = xr.Dataset({"accuracy_before": (dims, before), "accuracy_after": (dims, before * (1 + gain / 100)),
                     "loss_before": (dims, before), "loss_after": (dims, before),
                     "in_situ_evaluations": (dims, np.broadcast_to(np.array([12.0, 20.0, 0.0])[:, None, None, None],
                                                                   gain.shape))},
                    coords={"method": methods, "s0": [0.02], "st": [0.3], "seed": np.arange(seeds)})
    riv = _rivals_at("unused", {"rivals_regime": ds}, 0.02, 0.3)
    assert list(riv) == ["pat", "gift"]
    assert riv["pat"]["pct"] == pytest.approx(61.0) and riv["gift"]["pct"] == pytest.approx(2.0)
    assert riv["pat"]["chip_evaluations"] == 20 and riv["gift"]["n"] == seeds


def test_figures_without_their_inputs_say_what_they_need(tmp_path, monkeypatch):
    monkeypatch.setattr(paper_figures._build, "unavailable", lambda job, fixed=None: "needs gift_theory.finetune.run_finetune")
    res = build("tiny", only="performance_gift", data_dir=str(tmp_path), figure_dir=str(tmp_path), progress=False)
    assert res["figures"][0]["status"].startswith("RuntimeError: needs gift_theory.finetune.run_finetune")
    assert res["figures"][0]["path"] is None and not os.listdir(tmp_path)
    for name in ("example_fine_tuning", "bound_region", "error_ladder"):
        entry = build("tiny", only=name, data_dir=str(tmp_path), figure_dir=str(tmp_path), progress=False)["figures"][0]
        assert entry["status"] == "drawn" or "needs " in entry["status"], entry


@pytest.mark.parametrize("kind", ["uniform", "laplace", "multiplicative", "awgn"])
def test_paper_noise_laws_map_exactly_onto_the_effects(kind, x64):
    """U(-st, st), Laplace(0, st), multiplicative std st: check support / mean |n| / std by sampling."""
    st = 0.3
    s, effects = true_noise(kind, st)
    phys = gt.Physics.parse(list(effects), s=s)
    if kind == "multiplicative":
        assert s == 0.0 and phys.params()["m"] == pytest.approx(st)
        return
    arch = gt.Architecture((50, 4))
    noise = gt.sample_noise(jax.random.PRNGKey(1), arch, phys, (400,), jax.numpy.float64)
    n = np.asarray(noise["a0"] if "a0" in noise else next(iter(noise.values()))).ravel() * s
    m = n.size  # 20 000 draws: tolerances are 4.5 standard errors
    if kind == "uniform":  # U(-st, st): |n| <= st, E|n| = st / 2
        assert np.abs(n).max() <= st + 1e-12
        assert abs(np.abs(n).mean() - st / 2) < 4.5 * (st / math.sqrt(12)) / math.sqrt(m)
    elif kind == "laplace":  # Laplace(0, b = st): E|n| = b, sd|n| = b
        assert abs(np.abs(n).mean() - st) < 4.5 * st / math.sqrt(m)
    else:
        assert abs(n.std() - st) < 4.5 * st / math.sqrt(2 * m)


def test_an_mnist_folder_reaches_the_jobs_under_run_finetune_s_name():
    """``--mnist-folder DIR``: the GIFT sweeps pass it as run_finetune's ``data_folder`` (a wrong key
    would fail every point); a job whose library function takes no folder says so once."""
    import inspect

    from gift_theory.finetune import run_ceiling, run_finetune

    S = paper_figures.sweeps("tiny", mnist_folder="/some/idx")
    for name in ("gift_awgn_deep", "extended", "variants"):
        assert S[name].fixed["dataset"] == "mnist" and S[name].fixed["options"]["data_folder"] == "/some/idx"
        assert _jobs.unavailable(S[name].job, S[name].fixed) is None
    assert "data_folder" in inspect.signature(run_finetune).parameters
    ceil = _jobs.unavailable(S["ceiling_deep"].job, S["ceiling_deep"].fixed)
    assert (ceil is None) == ("data_folder" in inspect.signature(run_ceiling).parameters)


def test_cli_bad_input_is_one_line_and_exit_2(capsys, tmp_path):
    from gift_theory.cli import main

    assert main(["figures", "--only", "no_such_figure"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no_such_figure" in err
    # the MNIST folder is --data-folder as for every command that trains (--mnist-folder: the same option)
    for flag in ("--data-folder", "--mnist-folder"):
        assert main(["figures", flag, str(tmp_path / "nope"), "--draw-only"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--data-folder" in err


@pytest.mark.slow
def test_real_jobs_on_a_tiny_net():
    """The job functions against the real library: one GIFT point and one estimator point."""
    if _jobs.unavailable("paper_figures._jobs:gift_job"):
        pytest.skip("gift_theory.finetune is not in this checkout")
    sc = paper_figures.SCALES["tiny"]
    r = _jobs.gift_job("shallow", 0.1, 0.2, 0, arch=sc.nets["shallow"], dataset="digits", options=sc.options)
    for k in ("loss_before", "loss_after", "accuracy_before", "accuracy_after", "test_loss_before",
              "test_loss_after", "test_accuracy_before", "test_accuracy_after", "in_situ_evaluations", "seconds"):
        assert np.isfinite(r[k]), k
    assert "st" not in r and r["s_true"] == 0.2
    assert 0 <= r["accuracy_after"] <= 1 and r["loss_after"] > 0
    e = _jobs.estimator_job("score_paper", 64, 2, 0, dataset="digits", arch=sc.est_arch, s0=0.1, seed=0,
                            ref_K2=sc.est_ref_K2)
    # score_paper targets -(s/2) d/ds grad J: rescaled, its error is measured against the same reference
    assert e["rel_error"] > 0 and e["rel_error_rescaled"] > 0 and e["ref_rel_se"] > 0
    assert 0 <= e["rel_error_debiased"] <= e["rel_error_rescaled"]


def test_heatmap_colour_is_the_intervals_end_nearest_zero():
    from paper_figures._plot import interval_colour

    c = interval_colour([2.0, -3.0, 1.0, np.nan, 0.5], [1.0, 1.0, 2.0, 1.0, np.nan])
    np.testing.assert_allclose(c, [1.0, -2.0, 0.0, np.nan, 0.5])  # no interval (one seed): the mean
