"""Figures of the lab: each function returns a matplotlib Figure with labelled axes, draws into a
given ax / fig, selects no backend and writes nothing; the CLI's savers write them atomically."""

import dataclasses
import os
import types

import jax
import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

import gift_theory as gt
from gift_theory.lab import Model, simulate_measurement
from gift_theory.lab import predictive_moments
from gift_theory.lab import diagnosis_figures, error_ladder, fit_figures, moments_figure, save_figures, where_figure


@pytest.fixture(autouse=True)
def no_backend_no_files(monkeypatch, tmp_path):
    """Fail if a figure function selects a backend; run in an empty folder to see any file it writes."""
    def refuse(*a, **k):
        raise AssertionError("a figure function called matplotlib.use")

    monkeypatch.setattr(matplotlib, "use", refuse)
    monkeypatch.chdir(tmp_path)


@pytest.fixture(scope="module")
def meas():
    arch = gt.Architecture((3, 5, 2))
    params = gt.init_params(jax.random.PRNGKey(0), arch, gain=1.5)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (40, 3)), np.float64)
    truth = gt.Physics.parse(["awgn=0.05", "shot=0.02"])
    return simulate_measurement(jax.random.PRNGKey(2), params, x, truth, shots=8, taps=True)


@pytest.fixture(scope="module")
def moments(meas):
    k = jax.random.PRNGKey(3)
    before = predictive_moments(k, Model(gt.Physics.create(s=0.08)), meas, label="before")
    after = predictive_moments(k, Model(gt.Physics.parse(["awgn=0.05", "shot=0.02"])), meas, label="after")
    return before, after


def _where_stats(rows=7, names=("mean_z", "log_var_ratio", "excess_kurtosis")):
    rng = np.random.default_rng(0)
    return {"rows": [f"{1 + (i > 4)}:{i % 5}" for i in range(rows)],
            "maps": {k: rng.normal(size=(rows, 6)) for k in names}, "worst": []}


def _labelled(fig):
    axes = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    assert axes
    for ax in axes:
        assert ax.get_xlabel().strip(), ax.get_title()
    assert any(ax.get_ylabel().strip() for ax in axes)


def test_moments_are_the_data_s_and_the_model_s(meas, moments):
    before, after = moments
    for li, Y in enumerate(meas.layers()):
        np.testing.assert_array_equal(after.mean[li], Y.mean(1))
        np.testing.assert_array_equal(after.var[li], Y.var(1, ddof=1))
    # the true model's standardised mean residuals are N(0, 1): their mean square is 1 within its se
    z2 = np.concatenate([after.mean_z(li).ravel() ** 2 for li in range(len(after.layer_ids))])
    assert abs(z2.mean() - 1) < 4 * z2.std() / np.sqrt(z2.size)
    # the wrong (awgn-only, too noisy at the origin) model's log variance ratios are off on average
    lr, sd = before.log_var_ratio(1)
    assert sd == pytest.approx(np.sqrt(2 / 7 + 2 / (after.K - 1)))
    assert after.K == 32 and after.layer_ids == (1, 2)


def test_moments_figure_returns_a_labelled_figure_and_uses_a_given_fig(moments, tmp_path):
    fig = moments_figure(list(moments), 2)
    assert isinstance(fig, Figure) and len(fig.axes) == 4
    _labelled(fig)
    titles = " ".join(ax.get_title() for ax in fig.axes)
    assert "mean" in titles and "variance" in titles and "signal" in titles
    legend = " ".join(t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts())
    assert "before" in legend and "after" in legend and "identity" in legend
    host = Figure()
    sub = host.subfigures(1, 2)[1]
    assert moments_figure(moments[1], 1, fig=sub) is host and len(host.axes) == 4
    assert os.listdir(tmp_path) == []


def test_each_point_s_bar_spans_its_measured_moment_plus_minus_two_standard_errors(moments):
    """Panels (a) and (b) draw each cell's bar (one broken line per model): at the model's mean
    (variance), from the measured value less two standard errors to it plus two (the mean's
    sqrt(v / r), the variance's v sqrt(2 / (r - 1)))."""
    li, m = 1, moments[1]
    fig = moments_figure(list(moments), 2)
    a_mean, a_var = fig.axes[:2]
    Y, V, r = m.mean[li].ravel(), m.var[li].ravel(), m.r
    for ax, x_of, y, half in ((a_mean, lambda mm: mm.model_mean[li].ravel(), Y, 2 * np.sqrt(V / r)),
                              (a_var, lambda mm: mm.model_var[li].ravel(), V, 2 * V * np.sqrt(2.0 / (r - 1)))):
        bars = [ln for ln in ax.get_lines() if np.isnan(ln.get_ydata()).any()]
        assert len(bars) == len(moments)  # one line of bars per model, in the models' order
        for line, mm in zip(bars, moments):
            xs, ys = (np.asarray(v, float).reshape(-1, 3) for v in line.get_data())
            assert np.isnan(xs[:, 2]).all() and np.isnan(ys[:, 2]).all()  # broken after each bar
            np.testing.assert_array_equal(xs[:, 0], x_of(mm))
            np.testing.assert_array_equal(xs[:, 1], x_of(mm))
            np.testing.assert_allclose(ys[:, 0], y - half, rtol=1e-12)
            np.testing.assert_allclose(ys[:, 1], y + half, rtol=1e-12)
    labels = [t.get_text() for t in a_mean.get_legend().get_texts()]
    assert labels == ["before", "after", "identity"]  # each model once (its points), not once per bar


@pytest.mark.parametrize("shift, corner", [(-1.0, "lower right"), (1.0, "upper left")])
def test_a_moments_legend_sits_on_the_side_of_the_diagonal_the_points_are_not(moments, shift, corner):
    """Panels (a) and (b) plot measured against model: with the model's means (variances) below the
    measured ones every point is above the diagonal, and the legend goes below it; and the reverse."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    m = moments[1]
    moved = dataclasses.replace(m, model_mean=[a + shift for a in m.model_mean],
                                model_var=[a * np.exp(2 * shift) for a in m.model_var])
    fig = moments_figure(moved, 2)
    FigureCanvasAgg(fig).draw()
    for ax in fig.axes[:2]:
        box, at = ax.get_legend().get_window_extent(), ax.get_window_extent()
        right, low = (box.x0 + box.x1) / 2 > (at.x0 + at.x1) / 2, (box.y0 + box.y1) / 2 < (at.y0 + at.y1) / 2
        assert (right and low) if corner == "lower right" else (not right and not low), (ax.get_title(), box, at)


def test_where_figure_has_one_colour_scale_the_bin_edges_and_marks_the_significant_cells(tmp_path):
    stats = _where_stats()
    stats["edges"] = np.linspace(-2.0, 2.0, 7)
    stats["maps"]["mean_z"][2, 3] = 3.5        # beside an alarming value elsewhere: pale, not marked
    stats["maps"]["log_var_ratio"][0, 0] = 15.0  # significant: outlined
    stats["maps"]["excess_kurtosis"][1, 1] = 9.0  # not normal in its tails: shown, not marked
    stats["maps"]["mean_z"][6, 5] = np.nan       # an empty bin
    fig = where_figure(stats)
    assert isinstance(fig, Figure)
    panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert len(panels) == 3 and len(bars) == 1  # one scale for every panel: a 3 reads as a 3 everywhere
    assert len({p.images[0].get_clim() for p in panels}) == 1 and panels[0].images[0].get_clim()[1] >= 15.0
    assert panels[0].get_ylabel().startswith("layer:neuron") and bars[0].get_ylabel().strip()
    assert [t.get_text() for t in panels[0].get_xticklabels()] == [f"{e:.2g}" for e in stats["edges"]]
    assert "pre-activation" in panels[0].get_xlabel()
    # outlined: the cells beyond the family-wise threshold over the two marked maps, no others
    from scipy import stats as st

    zc = st.norm.isf(0.01 / (2 * (2 * 7 * 6 - 1)))
    for p, name in zip(panels, ["mean_z", "log_var_ratio", "excess_kurtosis"]):
        want = 0 if name == "excess_kurtosis" else int(np.sum(np.nan_to_num(np.abs(stats["maps"][name])) > zc))
        assert len(p.patches) == want, name
    assert len(panels[1].patches) == 1 and f"{zc:.2f}" in fig._suptitle.get_text()
    texts = [label for a in panels[1].artists for label in getattr(a, "labels", ())]  # each cell's value, in it
    assert len(texts) == 7 * 6 and f"{stats['maps']['log_var_ratio'][0, 1]:.1f}" in texts
    assert len([label for a in panels[0].artists for label in getattr(a, "labels", ())]) == 7 * 6 - 1  # not the empty bin
    assert fig.get_layout_engine() is not None
    # every panel spans the same rows (row 0 at the top); only the first names them
    assert {p.get_ylim() for p in panels} == {(6.5, -0.5)}
    assert [t.get_text() for t in panels[0].get_yticklabels()] == stats["rows"]
    assert [len(p.get_yticks()) for p in panels[1:]] == [0, 0]
    given = Figure()
    assert where_figure(stats, fig=given) is given
    assert os.listdir(tmp_path) == []


def test_the_where_figure_s_cell_values_are_the_pixels_a_text_per_cell_draws():
    # the cell values are one artist (thousands of Texts cost seconds to make, lay out and draw):
    # its pixels must be those of a Text per cell -- white on the strong colours, none in an empty bin
    import io

    stats = _where_stats()
    stats["maps"]["mean_z"][2, 3] = 6.0
    stats["maps"]["mean_z"][6, 5] = np.nan

    def pixels(values):  # a fresh figure drawn once (a constrained layout moves on a second draw)
        fig = where_figure(stats)
        panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
        lim = panels[0].images[0].get_clim()[1]
        for ax, name in zip(panels, stats["maps"]):
            if values == "one artist":
                continue
            (artist,) = [a for a in ax.artists if hasattr(a, "labels")]
            artist.remove()
            for (i, j), v in np.ndenumerate(np.asarray(stats["maps"][name], float)):
                if values == "a Text per cell" and np.isfinite(v):
                    ax.text(j, i, f"{v:.1f}", ha="center", va="center", fontsize=7,
                            color="white" if abs(v) > 0.6 * lim else "black", in_layout=False)
        png = io.BytesIO()  # savefig: a layout pass with drawing turned off, then the drawing
        fig.savefig(png, format="png")
        return png.getvalue()

    fast, slow, blank = pixels("one artist"), pixels("a Text per cell"), pixels("none")
    assert fast == slow
    assert fast != blank  # the values are drawn


def test_error_ladder_draws_into_a_given_ax(tmp_path):
    rungs = [("awgn", 40.0, 3.0, 1e-5), ("awgn + shot", 8.0, 3.0, 0.3)]
    fig = error_ladder(rungs, 7.0, 2.0)
    _labelled(fig)
    host = Figure()
    ax = host.add_subplot(1, 2, 2)
    assert error_ladder(rungs, 7.0, 2.0, ax=ax) is host and ax.get_ylabel() == "held-out discrepancy"
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
def test_savers_write_atomically_where_told(meas, tmp_path):
    cmp = types.SimpleNamespace(discrepancy=10.0, se=2.0, p_value=0.2, noise_floor=9.0, floor_se=2.0)
    res = types.SimpleNamespace(ladder=[("awgn", cmp), ("awgn + shot", cmp)], comparison_after=cmp,
                                before=Model(gt.Physics.create(s=0.08)),
                                after=Model(gt.Physics.parse(["awgn=0.05", "shot=0.02"])))
    out = fit_figures(res, str(tmp_path / "fit"), meas=meas)
    assert sorted(os.path.basename(p) for p in out) == ["ladder.png", "moments_layer1.png", "moments_layer2.png",
                                                        "ppc_layer1.png", "ppc_layer2.png"]
    # every PNG with its numbers beside it, as netCDF
    assert sorted(os.listdir(tmp_path / "fit")) == sorted([os.path.basename(p) for p in out]
                                                          + [os.path.basename(p)[:-4] + ".nc" for p in out])
    cand = types.SimpleNamespace(effects=("shot",), comparison=cmp, model=res.after)
    diag = types.SimpleNamespace(baseline_comparison=cmp, ranking=[cand], where=_where_stats(), baseline=res.before,
                                 held_out=np.arange(40))  # the shapes of the fit above: no new compilation
    out = diagnosis_figures(diag, str(tmp_path / "diag"))  # the predictive figures are the fit's, above
    assert sorted(os.path.basename(p) for p in out) == ["comparison.png", "ladder.png", "where.png"]
    for p in out:
        with open(p, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert save_figures({}, str(tmp_path / "none")) == []
    assert not [f for d, _, fs in os.walk(tmp_path) for f in fs if f.startswith(".tmp-")]


def _fit_like(meas):
    cmp = types.SimpleNamespace(discrepancy=10.0, se=2.0, p_value=0.2, noise_floor=9.0, floor_se=2.0)
    return types.SimpleNamespace(ladder=[("awgn", cmp), ("awgn + shot", cmp)], comparison_after=cmp,
                                 before=Model(gt.Physics.create(s=0.08)),
                                 after=Model(gt.Physics.parse(["awgn=0.05", "shot=0.02"])))


@pytest.mark.slow
def test_two_processes_write_the_same_files_as_one_and_share_the_drawing(meas, tmp_path, monkeypatch):
    """``processes=2``: a helper process writes some of the files (every netCDF, as it is handed
    over), and every file (PNG and netCDF) is byte for byte the one a single process writes. Which figures this process drew is read
    from the private ``_drawing.draw_to`` (the sharing is invisible in the files, by design)."""
    from gift_theory.lab import _drawing

    one = fit_figures(_fit_like(meas), str(tmp_path / "one"), meas=meas, where=_where_stats(), processes=1)
    here = []
    draw_to = _drawing.draw_to
    monkeypatch.setattr(_drawing, "draw_to", lambda d, p: here.append(os.path.basename(p)) or draw_to(d, p))
    two = fit_figures(_fit_like(meas), str(tmp_path / "two"), meas=meas, where=_where_stats(), processes=2)
    assert [os.path.basename(p) for p in two] == [os.path.basename(p) for p in one]
    assert sorted(os.listdir(tmp_path / "two")) == sorted(os.listdir(tmp_path / "one"))
    for name in os.listdir(tmp_path / "one"):
        with open(tmp_path / "one" / name, "rb") as a, open(tmp_path / "two" / name, "rb") as b:
            assert a.read() == b.read(), name
    # the helper wrote at least one file (the numbers files first, while this process draws), this process the others
    assert 0 < len(here) < len(os.listdir(tmp_path / "two")) and not [n for n in here if n.endswith(".nc")], here
    # each layer's figure is the one its function draws from every layer's numbers (the set sends
    # a helper one layer's; the tap's title still says tap)
    from gift_theory._model import named_subkey

    res, k = _fit_like(meas), named_subkey(jax.random.PRNGKey(0), "figure_moments")
    mom = [predictive_moments(k, res.before, meas, label="before: awgn"),
           predictive_moments(k, res.after, meas, label="after: " + " + ".join(res.after.effects))]
    direct = save_figures({"moments_layer1.png": moments_figure(mom, 1)}, str(tmp_path / "direct"))[0]
    with open(direct, "rb") as a, open(tmp_path / "two" / "moments_layer1.png", "rb") as b:
        assert a.read() == b.read()


@pytest.mark.slow
def test_a_diagnosis_s_figures_drawn_while_it_runs_are_the_files_drawn_after_it(meas, tmp_path, monkeypatch):
    """``DiagnosisFigures``: the figures that need only the ranking handed over before the rest (as
    ``gift diagnose`` does while it localises), a helper drawing them and writing every netCDF:
    the same files, byte for byte, in the same order, as :func:`diagnosis_figures` after the
    diagnosis in one process; and a diagnosis that fails after its ranking leaves the folder as it
    was (the files are drawn out of sight and moved in at the end)."""
    from gift_theory.lab import DiagnosisFigures, _drawing

    res = _fit_like(meas)
    cand = types.SimpleNamespace(effects=("shot",), comparison=res.comparison_after, model=res.after)
    diag = types.SimpleNamespace(baseline_comparison=res.comparison_after, ranking=[cand], where=_where_stats(),
                                 baseline=res.before, held_out=np.arange(40))
    after = diagnosis_figures(diag, str(tmp_path / "after"), meas=meas)
    here = []
    draw_to = _drawing.draw_to
    monkeypatch.setattr(_drawing, "draw_to", lambda d, p: here.append(os.path.basename(p)) or draw_to(d, p))
    with DiagnosisFigures(str(tmp_path / "during"), meas=meas, processes=2) as figures:
        figures.ranked(diag.baseline, diag.baseline_comparison, tuple(diag.ranking), diag.held_out)
        assert os.listdir(tmp_path / "during") and not [f for f in os.listdir(tmp_path / "during")
                                                         if not f.startswith(".")]  # nothing in sight yet
        during = figures.finish(diag)
    assert [os.path.basename(p) for p in during] == [os.path.basename(p) for p in after]
    assert [os.path.basename(p) for p in after][:3] == ["ladder.png", "comparison.png", "where.png"]
    assert sorted(os.listdir(tmp_path / "during")) == sorted(os.listdir(tmp_path / "after"))
    for name in os.listdir(tmp_path / "after"):
        with open(tmp_path / "after" / name, "rb") as a, open(tmp_path / "during" / name, "rb") as b:
            assert a.read() == b.read(), name
    assert not [n for n in here if n.endswith(".nc")] and len(here) < len(os.listdir(tmp_path / "during")), here

    old = tmp_path / "old"
    old.mkdir()
    (old / "where.png").write_bytes(b"an earlier run's")
    with pytest.raises(RuntimeError, match="after the ranking"):
        with DiagnosisFigures(str(old), meas=meas, processes=2) as figures:
            figures.ranked(diag.baseline, diag.baseline_comparison, tuple(diag.ranking), diag.held_out)
            raise RuntimeError("the diagnosis failed after the ranking")
    assert os.listdir(old) == ["where.png"] and (old / "where.png").read_bytes() == b"an earlier run's"
    with pytest.raises(RuntimeError):  # a folder made for a run that failed is not left behind
        with DiagnosisFigures(str(tmp_path / "new" / "diagnose"), meas=meas, processes=1) as figures:
            figures.ranked(diag.baseline, diag.baseline_comparison, tuple(diag.ranking), diag.held_out)
            raise RuntimeError("the diagnosis failed after the ranking")
    assert not (tmp_path / "new").exists()


@pytest.mark.slow
def test_a_drawing_the_helper_cannot_do_is_done_here_and_its_error_raised_here(tmp_path, monkeypatch):
    from functools import partial

    good = partial(error_ladder, [("awgn", 10.0, 2.0, 0.2)], 9.0, 2.0)
    bad = partial(error_ladder, [("awgn", 10.0)], 9.0, 2.0)  # a rung without its se: fails in any process
    with pytest.raises(IndexError):
        error_ladder([("awgn", 10.0)], 9.0, 2.0)
    # the helper takes the first drawing while this process waits (meanwhile) and fails it; this
    # process draws the others, then that one again, and raises
    import time

    with pytest.raises(IndexError):
        save_figures({"a.png": bad, "b.png": good, "c.png": good, "d.png": good}, str(tmp_path / "bad"), processes=2,
                     meanwhile=lambda: time.sleep(1.0))
    assert sorted(os.listdir(tmp_path / "bad")) == ["b.png", "c.png", "d.png"]
    # a Figure drawn already does not go to a helper; neither does a drawing that does not pickle
    out = save_figures({"a.png": good(), "b.png": good}, str(tmp_path / "figs"), processes=2)
    out += save_figures({"c.png": lambda: good(), "d.png": good}, str(tmp_path / "figs"), processes=2)
    # a helper that cannot start costs nothing but time; what runs meanwhile runs once either way
    ran = []
    with monkeypatch.context() as m:
        m.setattr("sys.executable", str(tmp_path / "no-python"))
        out += save_figures({"e.png": good, "f.png": good}, str(tmp_path / "figs"), processes=2,
                            meanwhile=lambda: ran.append(2))
    out += save_figures({"g.png": good}, str(tmp_path / "figs"), processes=1, meanwhile=lambda: ran.append(1))
    assert ran == [2, 1]
    assert sorted(os.listdir(tmp_path / "figs")) == [f"{c}.png" for c in "abcdefg"] == [os.path.basename(p) for p in out]
    with pytest.raises(KeyError):  # an error meanwhile is raised once the helper's drawing in hand is written
        save_figures({"a.png": good, "b.png": good}, str(tmp_path / "meanwhile"), processes=2,
                     meanwhile=lambda: {}["power"])
    assert not [f for d, _, fs in os.walk(tmp_path) for f in fs if f.startswith(".tmp-")]


def test_the_figure_processes_setting_is_1_or_2(tmp_path, capsys, monkeypatch):
    from gift_theory.cli import main

    monkeypatch.setenv("GIFT_FIGURE_PROCESSES", "3")
    code = main(["diagnose", str(tmp_path / "chip.npz")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err == "GIFT_FIGURE_PROCESSES=3: needs 1 or 2", err


def test_the_law_panels_numbers_are_calibrated_under_the_true_model_and_see_a_wrong_spread(meas):
    from gift_theory.lab import where_it_fails
    from gift_theory.lab import correlation_figure, law_figure, pit_figure
    from scipy import stats as st

    truth = Model(gt.Physics.parse(["awgn=0.05", "shot=0.02"]))
    w = where_it_fails(jax.random.PRNGKey(4), truth, meas)
    assert len(w["edges"]) == 7 and np.all(np.diff(w["edges"]) > 0)
    for l, counts in w["pit"].items():
        share = counts / counts.sum()
        band = np.sqrt(0.1 * 0.9 / w["pit_cells"][l])  # one value per cell: the conservative sd
        assert np.all(np.abs(share - 0.1) < 4 * band), (l, share)
    z = np.concatenate([C[np.triu_indices_from(C, 1)] for C in w["correlation"].values()])
    assert abs(z.mean()) < 4 / np.sqrt(z.size) + 0.3 and np.all(np.abs(z) < st.norm.isf(0.005 / z.size))
    for q in w["qq"].values():
        assert np.max(np.abs(q["measured"][4:-4] - q["model"][4:-4])) < 0.3
    narrow = where_it_fails(jax.random.PRNGKey(4), Model(gt.Physics.create(s=0.02)), meas)
    for l, q in narrow["qq"].items():  # the model's spread too small: the measured shots' quantiles fan out
        assert q["measured"][-2] > 1.5 * q["model"][-2] and q["measured"][1] < 1.5 * q["model"][1]
        share = narrow["pit"][l] / narrow["pit"][l].sum()
        assert share[0] + share[-1] > 0.3  # a U: many shots beyond every model shot
    for f in (pit_figure(narrow), correlation_figure(narrow), law_figure(narrow)):
        _labelled(f)


def test_a_difference_of_discrepancies_has_its_paired_bootstrap_standard_error():
    from gift_theory.lab import Comparison, discrepancy_difference
    # private: the statistic on bootstrap replicates and (below) its memory budget, the kernel of the public difference
    from gift_theory.lab._compare import _q_of
    from gift_theory.lab._qtest import q_test  # private: builds two comparisons from hand-made channel values

    rng = np.random.default_rng(0)
    n, C = 60, 10
    shared = rng.normal(size=(n, C))  # what two models' channels share on the same inputs cancels in the difference
    Ta = shared + 0.8 + 0.2 * rng.normal(size=(n, C))
    Tb = shared + 0.6 + 0.2 * rng.normal(size=(n, C))

    def comp(T):
        Q = q_test(T)[0]
        return Comparison(Q, 1.0, 0.0, 1.0, 0.5, np.zeros(n), np.zeros(1), (1,), np.zeros((n, 1)), channel_values=T)

    a, b = comp(Ta), comp(Tb)
    assert _q_of(Ta[None])[0] == pytest.approx(a.discrepancy)
    delta, se = discrepancy_difference(a, b)
    assert delta == pytest.approx(a.discrepancy - b.discrepancy)
    # against the bootstrap of each alone, added as if independent: the shared part cancels in the pair
    idx = np.random.default_rng(1).integers(0, n, size=(1000, n))
    alone = np.hypot(np.std(_q_of(Ta[idx])), np.std(_q_of(Tb[idx])))
    assert 0 < se < 0.5 * alone
    # the replicates in steps of 7: the same standard error
    # private: the bootstrap's memory budget, a constant no argument sets
    from gift_theory.lab import _compare

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_compare, "BOOTSTRAP_BYTES", 7 * 8 * n * C)
        assert discrepancy_difference(a, b) == (delta, pytest.approx(se, rel=1e-12))
    assert discrepancy_difference(a, a) == (0.0, 0.0)
    assert np.isnan(discrepancy_difference(a, dataclasses.replace(b, channel_values=None))[1])


def test_the_pair_plot_draws_the_intervals_gift_fit_reports():
    from gift_theory.lab import pairs_figure
    # private: the numbers the pair figure draws, beside it on disk but not an API
    from gift_theory.lab._figure_sets import pairs_data
    from scipy import stats as st

    cov = np.array([[0.01, -0.008], [-0.008, 0.02]])
    joint = {"params": ["s", "q"], "scale": ["log", "log"], "centre": [np.log(0.1), np.log(0.03)],
             "estimate": [0.1, 0.031], "cov": cov.tolist(), "level": 0.95, "dof": 29}
    fig = pairs_figure(joint)
    assert len(fig.axes) == 4
    t = st.t.ppf(0.975, 29)
    lo, hi = np.exp(np.log(0.1) - t * 0.1), np.exp(np.log(0.1) + t * 0.1)  # moment_intervals' interval of s
    labels = [tx.get_text() for ax in fig.axes if ax.get_legend() for tx in ax.get_legend().get_texts()]
    assert f"95%: [{lo:.3g}, {hi:.3g}]" in labels
    assert any("-0.57" in tx.get_text() for ax in fig.axes for tx in ax.texts)  # the correlation
    ds = pairs_data(joint)
    np.testing.assert_allclose(ds["cov_fit_scale"].values, cov)


def test_the_demo_s_bars_say_what_their_colours_mean():
    # private: the demo's bar figure, which only a full `gift demo` run draws otherwise
    from gift_theory.cli._demo_parts import plot_finetune

    rows = [{"method": m, "loss_before": 1.0, "loss_after": v} for m, v in (("gift", 0.9), ("spsa", 1.1), ("ift", 1.0))]
    curve = {k: [0.0, 1.0] for k in ("alpha", "truth", "truth_se", "predicted", "predicted_model_C2", "chip_alpha",
                                     "chip_dJ", "chip_se")}
    curve["method"] = "gift"
    host = Figure()
    fig = plot_finetune(rows, curve, s0=0.05, st=0.2, ax=host.subplots(1, 2))
    legend = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert legend == ["w0 (no fine-tuning)", "lower loss than w0", "higher loss than w0", "w0 returned (the same loss)"]


def test_each_command_has_a_figure_folder_of_its_own(tmp_path):
    import argparse
    import json

    from gift_theory import GiftInputError
    # private: the figure-folder rule every lab command shares, without running one
    from gift_theory.cli._labargs import figure_dir

    args = argparse.Namespace(measurement=str(tmp_path / "chip.npz"), figures=None, json=False)
    folders = {c: figure_dir(args, c) for c in ("compare", "diagnose", "fit")}
    assert folders == {c: str(tmp_path / "chip_gift" / c) for c in folders}
    assert figure_dir(argparse.Namespace(measurement="chip.npz", figures=None, json=True), "fit") is None
    os.makedirs(folders["compare"])
    with open(os.path.join(folders["compare"], "figures.json"), "w") as fh:
        json.dump({"command": "compare"}, fh)
    given = argparse.Namespace(measurement="chip.npz", figures=folders["compare"], json=True)
    assert figure_dir(given, "compare") == folders["compare"]  # its own folder: rewritten
    with pytest.raises(GiftInputError, match="holds the figures of gift compare"):
        figure_dir(given, "diagnose")
