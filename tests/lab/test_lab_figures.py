"""Figures of the lab: each function returns a matplotlib Figure with labelled axes, draws into a
given ax / fig, selects no backend and writes nothing; the CLI's savers write them atomically."""

import os
import types

import jax
import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

import gift_theory as gt
from gift_theory.lab import Model, simulate_measurement
from gift_theory.lab._compare import predictive_moments
from gift_theory.lab._figures import (diagnosis_figures, error_ladder, fit_figures, moments_figure, save_figures,
                                      where_figure)


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


def test_where_figure_labels_axes_colourbars_and_bins(tmp_path):
    stats = _where_stats()
    fig = where_figure(stats)
    assert isinstance(fig, Figure)
    panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert len(panels) == 3 and len(bars) == 3
    assert panels[0].get_ylabel().startswith("layer:neuron")
    assert all(b.get_ylabel().strip() for b in bars)  # every colour bar says what its colour is
    texts = [t.get_text() for t in panels[1].texts]
    assert len(texts) == 7 * 6 and f"{stats['maps']['log_var_ratio'][0, 0]:.1f}" in texts
    assert fig.get_layout_engine() is not None  # constrained: colour bars do not overlap the next panel
    fig.canvas.draw()  # resolve the layout
    for bar, nxt in zip(bars[:-1], panels[1:]):
        assert bar.get_position().x1 <= nxt.get_position().x0
    given = Figure()
    assert where_figure(stats, fig=given) is given
    assert os.listdir(tmp_path) == []


def test_error_ladder_draws_into_a_given_ax(tmp_path):
    rungs = [("awgn", 40.0, 3.0, 1e-5), ("awgn + shot", 8.0, 3.0, 0.3)]
    fig = error_ladder(rungs, 7.0, 2.0)
    _labelled(fig)
    host = Figure()
    ax = host.add_subplot(1, 2, 2)
    assert error_ladder(rungs, 7.0, 2.0, ax=ax) is host and ax.get_ylabel() == "held-out discrepancy"
    assert os.listdir(tmp_path) == []


def test_savers_write_atomically_where_told(meas, tmp_path):
    cmp = types.SimpleNamespace(discrepancy=10.0, se=2.0, p_value=0.2, noise_floor=9.0, floor_se=2.0)
    res = types.SimpleNamespace(ladder=[("awgn", cmp), ("awgn + shot", cmp)], comparison_after=cmp,
                                before=Model(gt.Physics.create(s=0.08)),
                                after=Model(gt.Physics.parse(["awgn=0.05", "shot=0.02"])))
    out = fit_figures(res, str(tmp_path / "fit"), meas=meas)
    assert sorted(os.path.basename(p) for p in out) == ["ladder.png", "moments_layer1.png", "moments_layer2.png"]
    cand = types.SimpleNamespace(effects=("shot",), comparison=cmp, model=res.after)
    diag = types.SimpleNamespace(baseline_comparison=cmp, ranking=[cand], where=_where_stats(), baseline=res.before,
                                 held_out=np.arange(40))  # the shapes of the fit above: no new compilation
    out = diagnosis_figures(diag, str(tmp_path / "diag"), meas=meas)
    assert sorted(os.path.basename(p) for p in out) == ["ladder.png", "moments_layer1.png", "moments_layer2.png",
                                                        "where.png"]
    for p in out:
        with open(p, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert save_figures({}, str(tmp_path / "none")) == []
    assert not [f for d, _, fs in os.walk(tmp_path) for f in fs if f.startswith(".tmp-")]
