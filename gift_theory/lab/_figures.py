"""Figures of the measurement loop: the error ladder, where the model fails, and the measured
moments beside the model's.

Plotting never recomputes the science: each function draws numbers already computed by
:func:`gift_theory.lab.fit_effects`, :func:`gift_theory.lab.diagnose`,
:func:`gift_theory.lab.where_it_fails` or :func:`gift_theory.lab._compare.predictive_moments`.
Every figure function takes ``ax=`` (one panel) or ``fig=`` (several panels: a Figure or a
SubFigure to draw into), returns the matplotlib Figure, never selects a backend and never
writes a file; :func:`save_figures` writes them (atomically) and the CLI calls it.
"""

from __future__ import annotations

import os

import numpy as np

from .._io import save_figure

#: the where-figure's statistics: panel title and colour-bar label (each is N(0, 1) under the model)
WHERE_LABELS = {
    "mean_z": ("mean: measured - model", "z of the mean residual"),
    "log_var_ratio": ("variance: log(measured / model)", "z of the log variance ratio"),
    "excess_kurtosis": ("noise shape: excess kurtosis", "z of the kurtosis difference"),
    "time_trend": ("trend over acquisition time", "z of the time trend"),
}
_COLORS = ("0.45", "tab:blue", "tab:orange", "tab:green")


def _new_figure(figsize):
    from matplotlib.figure import Figure  # no pyplot, no backend: the caller decides

    return Figure(figsize=figsize, layout="constrained")


def _root(fig_or_ax):
    return fig_or_ax.get_figure(root=True) if hasattr(fig_or_ax, "get_figure") else fig_or_ax


def error_ladder(rungs, noise_floor: float, floor_se: float, *, title: str = "error ladder", ax=None):
    """Discrepancy (with 2 se bars) of each model version against the floor band.

    Parameters
    ----------
    rungs : sequence of (label, discrepancy, se, p_value)
    noise_floor, floor_se : the measured shots' own floor and its standard error
    ax : matplotlib Axes to draw into (default: a new figure)

    Returns
    -------
    matplotlib.figure.Figure
    """
    if ax is None:
        ax = _new_figure((3.4 + 1.4 * len(rungs), 3.8)).add_subplot()  # + the legend beside the axes
    xs = np.arange(len(rungs))
    d = np.array([r[1] for r in rungs], float)
    se = np.array([r[2] for r in rungs], float)
    ax.axhspan(noise_floor - 2 * floor_se, noise_floor + 2 * floor_se, color="0.88", label="noise floor $\\pm$ 2 se")
    ax.axhline(noise_floor, color="0.5", lw=1)
    colors = ["tab:red" if r[3] < 0.01 else "tab:green" for r in rungs]
    ax.errorbar(xs, d, yerr=2 * se, fmt="none", ecolor="k", capsize=4, label="$\\pm$ 2 se")
    ax.scatter(xs, d, c=colors, zorder=3, s=40)
    for x, r in zip(xs, rungs):
        ax.annotate(f"p = {r[3]:.2g}", (x, r[1]), textcoords="offset points", xytext=(7, 4), fontsize=8)
    ax.set_xticks(xs)
    ax.set_xticklabels([r[0].replace(" + ", "\n+ ") for r in rungs], fontsize=8)
    ax.set_xlabel("model")
    ax.set_ylabel("held-out discrepancy")
    ax.set_title(title + "  (red: rejected, p < 0.01)", fontsize=10)
    ax.set_xlim(-0.5, len(rungs) - 0.2)  # room for the last p-value
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside: never over a point or label
    return _root(ax)


def where_figure(stats: dict, *, title: str = "where the model fails", fig=None):
    """Per-cell standardised statistics over (layer:neuron) x bins of the model's pre-activation,
    one heatmap per statistic, each bin's value written in it.

    ``stats`` is the output of :func:`gift_theory.lab.where_it_fails`: ``rows`` ("layer:neuron",
    0-based neurons) and for each statistic a (rows, bins) array of ``sum z / sqrt(count)``,
    N(0, 1) under the model.

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(stats["maps"])
    rows = list(stats["rows"])
    nr = len(rows)
    bins = np.asarray(stats["maps"][names[0]]).shape[1]
    if fig is None:
        fig = _new_figure((2.2 + 2.7 * len(names), 1.6 + 0.22 * nr))
    axes = np.atleast_1d(fig.subplots(1, len(names), sharey=True))
    font = 7 if nr <= 40 else 5 if nr <= 80 else 0  # values on the bins while they stay legible
    layer_of = [r.split(":")[0] for r in rows]
    breaks = [i - 0.5 for i in range(1, nr) if layer_of[i] != layer_of[i - 1]]
    for k, (ax, name) in enumerate(zip(axes, names)):
        M = np.asarray(stats["maps"][name], float)
        lim = max(float(np.nanmax(np.abs(M))) if np.isfinite(M).any() else 1.0, 3.0)
        # every statistic is standardised (N(0, 1) under the model): one symmetric scale
        im = ax.imshow(M, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
        head, cbar_label = WHERE_LABELS.get(name, (name, "z"))
        ax.set_title(head, fontsize=9)
        ax.set_xticks(range(bins))
        ax.set_xticklabels([str(b + 1) for b in range(bins)], fontsize=7)
        ax.set_xlabel("bin of the model's pre-activation\n(1 = lowest)", fontsize=8)
        for y in breaks:
            ax.axhline(y, color="k", lw=0.8)
        if font:
            for (i, j), v in np.ndenumerate(M):
                if np.isfinite(v):
                    ax.text(j, i, f"{v:.1f}", ha="center", va="center", fontsize=font,
                            color="white" if abs(v) > 0.6 * lim else "black")
        cb = fig.colorbar(im, ax=ax, shrink=0.9, aspect=30)
        cb.set_label(cbar_label, fontsize=8)
        cb.ax.tick_params(labelsize=7)
        if k == 0:
            step = max(1, int(np.ceil(nr / 60)))
            ax.set_yticks(range(0, nr, step))
            ax.set_yticklabels(rows[::step], fontsize=7 if nr <= 40 else 5)
            ax.set_ylabel("layer:neuron (neurons from 0)", fontsize=8)
    fig.suptitle(title + "   (each bin: sum of z / sqrt(count), N(0, 1) under the model; |z| > 3 stands out)",
                 fontsize=9)
    return _root(fig)


def moments_figure(moments, layer: int, *, fig=None, title: str | None = None):
    """Posterior-predictive check of one layer: each neuron's measured mean and variance against
    the model's across inputs, for one or several models (e.g. before and after a fit), and
    the residuals against the signal.

    Parameters
    ----------
    moments : a :class:`~gift_theory.lab._compare.Moments` or a sequence of them (same
        measurement, one per model; the first drawn in grey as "before")
    layer : the 1-based layer to draw (must be measured: the output, or a tap)
    fig : Figure or SubFigure to draw into (default: a new figure)

    Panels: (a) measured mean against the model's, error bars +-2 sqrt(v/r) from the shot
    count; (b) the same of the variance (log axes), error bars from its chi-square law;
    (c) the mean residual in z units against the model's mean (the signal); (d) the log
    variance ratio against the signal, with the +-2 sd band of pure shot noise.

    Returns
    -------
    matplotlib.figure.Figure
    """
    mlist = [moments] if hasattr(moments, "layer_ids") else list(moments)
    li = list(mlist[0].layer_ids).index(layer)
    if fig is None:
        fig = _new_figure((9.5, 7.6))
    (a_mean, a_var), (a_rz, a_rv) = fig.subplots(2, 2)
    colors = _COLORS if len(mlist) > 1 else _COLORS[1:]
    r = mlist[0].r
    Y, V = mlist[0].mean[li].ravel(), mlist[0].var[li].ravel()
    n, d = mlist[0].mean[li].shape
    for c, m in zip(colors, mlist):
        mu, v = m.model_mean[li].ravel(), m.model_var[li].ravel()
        kw = dict(fmt="o", ms=2.5, color=c, ecolor=c, elinewidth=0.4, alpha=0.5)
        a_mean.errorbar(mu, Y, yerr=2 * np.sqrt(V / r), label=m.label, **kw)
        a_var.errorbar(v, V, yerr=2 * V * np.sqrt(2.0 / (r - 1)), label=m.label, **kw)
        z = m.mean_z(li).ravel()
        lr, sd = m.log_var_ratio(li)
        a_rz.plot(mu, z, "o", ms=2.5, color=c, alpha=0.6,
                  label=f"{m.label}: rms z = {np.sqrt(np.mean(z ** 2)):.2f}")
        a_rv.plot(mu, lr.ravel(), "o", ms=2.5, color=c, alpha=0.6,
                  label=f"{m.label}: mean = {np.mean(lr):+.2f}")
    for ax, pts in ((a_mean, [Y] + [m.model_mean[li].ravel() for m in mlist]),
                    (a_var, [V] + [m.model_var[li].ravel() for m in mlist])):
        lo, hi = min(float(np.min(p)) for p in pts), max(float(np.max(p)) for p in pts)  # the points, not the bars
        ax.plot([lo, hi], [lo, hi], color="k", lw=0.8, ls="--", label="identity")
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

    a_var.set_xscale("log")
    a_var.set_yscale("log")
    for axis in (a_var.xaxis, a_var.yaxis):  # 1-2-5 labels: the default minor labels of a short range overlap
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())
    a_mean.set_xlabel("model mean")
    a_mean.set_ylabel("measured mean ($\\pm$ 2 se, r shots)")
    a_mean.set_title("(a) mean of each neuron and input", fontsize=9)
    a_var.set_xlabel("model variance")
    a_var.set_ylabel("measured variance ($\\pm$ 2 se)")
    a_var.set_title("(b) variance over shots", fontsize=9)
    a_rz.axhspan(-2, 2, color="0.9", zorder=0)
    a_rz.axhline(0, color="k", lw=0.8)
    a_rz.set_xlabel("signal: model mean")
    a_rz.set_ylabel("mean residual z (N(0, 1) under the model)")
    a_rz.set_title("(c) mean residual against the signal (band: $\\pm$ 2)", fontsize=9)
    sd = mlist[0].log_var_ratio(li)[1]  # the same r and K for every model
    a_rv.axhspan(-2 * sd, 2 * sd, color="0.9", zorder=0)
    a_rv.axhline(0, color="k", lw=0.8)
    a_rv.set_xlabel("signal: model mean")
    a_rv.set_ylabel("log(measured / model variance)")
    a_rv.set_title(f"(d) variance ratio against the signal (band: $\\pm$ 2 sd = {2 * sd:.2f})", fontsize=9)
    for ax in (a_mean, a_rz, a_rv):
        ax.xaxis.set_major_locator(MaxNLocator(7, steps=[1, 2, 2.5, 5, 10]))
    for ax in (a_mean, a_var, a_rz, a_rv):
        ax.legend(fontsize=7, loc="best", markerscale=2)
        ax.grid(alpha=0.3, lw=0.5)
    kind = "output" if layer == max(mlist[0].layer_ids) else "tap"
    fig.suptitle(title or f"layer {layer} ({kind}, {d} neurons): measured against model, {n} inputs x {r} shots "
                          f"(model: {mlist[0].K} shots)", fontsize=10)
    return _root(fig)


def time_figure(data: dict, *, title: str = "residual against acquisition time", fig=None):
    """Each measured layer's residual along the signal (the shot's relative gain against the
    model's mean of its input) in bins of acquisition time, with 2 se bands
    (:func:`gift_theory.lab._time.residual_in_time` computes it). A gain that drifts or wanders
    shows as a curve, a fixed error as a level away from 0, white noise as a flat band."""
    layers = [l for l in data if isinstance(l, int)]
    if fig is None:
        fig = _new_figure((6.4, 1.9 * max(len(layers), 1) + 0.6))
    axes = fig.subplots(max(len(layers), 1), 1, sharex=True, squeeze=False)[:, 0]
    for ax, l in zip(axes, layers):
        d = data[l]
        ok = d["count"] > 1
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.fill_between(d["t"][ok], (d["mean"] - 2 * d["se"])[ok], (d["mean"] + 2 * d["se"])[ok],
                        color="tab:blue", alpha=0.25, lw=0)
        ax.plot(d["t"][ok], d["mean"][ok], color="tab:blue", lw=1.2)
        ax.set_ylabel(f"layer {l}\nrelative gain", fontsize=8)
        ax.grid(alpha=0.3, lw=0.5)
    how = {"blocked": "each input's shots one after the other", "random": "each input's shots spread over the campaign"}
    axes[-1].set_xlabel(f"acquisition time t ({how.get(data.get('order'), 'order unknown')})")
    fig.suptitle(title, fontsize=10)
    return _root(fig)


def save_figures(figures: dict, folder: str) -> list[str]:
    """Write ``{file name: Figure}`` into ``folder`` (created), each atomically; the paths written."""
    return [save_figure(f, os.path.join(folder, name), bbox_inches="tight") for name, f in figures.items()]


def _moments_figures(key, models, meas) -> dict:
    from .._model import named_subkey
    from ._compare import predictive_moments

    k = named_subkey(key, "figure_moments")  # common random numbers: every model the same draws
    mom = [predictive_moments(k, m, meas, label=lab) for lab, m in models]
    return {f"moments_layer{l}.png": moments_figure(mom, l) for l in meas.layer_ids()}


def diagnosis_figures(diagnosis, folder: str, meas=None, key=None) -> list[str]:
    """The figures of a :class:`~gift_theory.lab.Diagnosis`, written to ``folder``: the error
    ladder of the baseline and the three best candidates, where the baseline fails, and
    (given the measurement) each measured layer's moments under the baseline and the
    top-ranked model on the held-out inputs, and with acquisition times each layer's residual
    against them (:func:`time_figure`)."""
    c = diagnosis.baseline_comparison
    rungs = [("awgn", c.discrepancy, c.se, c.p_value)] + [
        ("awgn + " + " + ".join(cand.effects), cand.comparison.discrepancy, cand.comparison.se, cand.comparison.p_value)
        for cand in diagnosis.ranking[:3]]
    figs = {"ladder.png": error_ladder(rungs, c.noise_floor, c.floor_se, title="baseline and best candidates")}
    if diagnosis.where is not None:
        figs["where.png"] = where_figure(diagnosis.where, title="baseline: where it fails")
    if meas is not None:
        import jax

        key = jax.random.PRNGKey(0) if key is None else key
        models = [("before: " + " + ".join(diagnosis.baseline.effects), diagnosis.baseline)]
        if diagnosis.ranking:
            top = diagnosis.ranking[0]
            models.append(("first ranked: " + " + ".join(top.model.effects), top.model))
        figs.update(_moments_figures(key, models, meas.subset(diagnosis.held_out)))
        if meas.t is not None:  # issue 48: the residual against acquisition time, per layer
            from .._model import named_subkey
            from ._time import residual_in_time

            figs["time.png"] = time_figure(residual_in_time(named_subkey(key, "figure_time"), diagnosis.baseline, meas),
                                           title="baseline: residual along the signal against acquisition time")
    return save_figures(figs, folder)


def fit_figures(result, folder: str, meas=None, key=None) -> list[str]:
    """The error ladder of a :class:`~gift_theory.lab.FitResult` and (given the measurement) each
    measured layer's moments before and after the fit, over all inputs, written to ``folder``."""
    a = result.comparison_after
    rungs = [(lab, c.discrepancy, c.se, c.p_value) for lab, c in result.ladder]
    figs = {"ladder.png": error_ladder(rungs, a.noise_floor, a.floor_se)}
    if meas is not None:
        import jax

        key = jax.random.PRNGKey(0) if key is None else key
        figs.update(_moments_figures(key, [("before: " + " + ".join(result.before.effects), result.before),
                                           ("after: " + " + ".join(result.after.effects), result.after)], meas))
    return save_figures(figs, folder)


def heatmaps(stats: dict, path: str, title: str = "where the model fails") -> str:
    """:func:`where_figure` written to ``path`` (atomically); the path."""
    return save_figure(where_figure(stats, title=title), path, bbox_inches="tight")
