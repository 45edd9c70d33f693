"""Figures of the measurement loop: the error ladder, where the model fails, and the measured
moments beside the model's.

Plotting never recomputes the science: each function draws numbers already computed by
:func:`gift_theory.lab.fit_effects`, :func:`gift_theory.lab.diagnose`,
:func:`gift_theory.lab.where_it_fails`, :func:`gift_theory.lab._compare.predictive_shots` or
the fit's intervals (the one exception, :func:`comparison_table`, bootstraps the paired
standard error of two discrepancies from their channel values). Every figure function takes
``ax=`` (one panel) or ``fig=`` (several panels: a Figure or a SubFigure to draw into), returns
the matplotlib Figure, never selects a backend and never writes a file;
:func:`._figure_sets.save_figures` writes them (atomically), each beside its numbers as netCDF (``*_data`` functions: the
``xarray.Dataset`` a figure draws), and the CLI calls it.
"""

from __future__ import annotations

import functools

import numpy as np

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


def _significance(m: int, alpha: float = 0.01) -> float:
    """The |z| beyond which one of ``m`` N(0, 1) cells is significant at family-wise ``alpha``
    (two-sided, Bonferroni)."""
    from scipy import stats

    return float(stats.norm.isf(alpha / (2.0 * max(m, 1))))


def _outline(ax, mask, color="k", lw=1.6):
    """A box around every True cell of ``mask`` (rows, cols) of an imshow."""
    from matplotlib.patches import Rectangle

    for i, j in zip(*np.nonzero(mask)):
        ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor=color, lw=lw, zorder=3))


#: statistics of the where-figure whose z is not normal in its tails (shown, not marked)
UNMARKED = ("excess_kurtosis",)


@functools.cache
def _cell_values_artist():
    """The artist class of a heatmap's cell values (made once, on first use: matplotlib is
    imported only when a figure is drawn)."""
    from matplotlib.artist import Artist
    from matplotlib.text import Text

    class CellValues(Artist):
        """Each finite cell's value of a heatmap (row i, column j at data (j, i)), written in its
        cell: what a Text per cell draws, pixel for pixel, drawn by one Text moved from cell to
        cell. A heatmap of a few hundred rows holds thousands of values; as one artist they
        cost no artist each to make, and nothing in the layout pass of a constrained layout
        (they sit inside their cells, so the layout need not measure them)."""

        zorder = 3  # a Text's

        def __init__(self, M, lim: float, fontsize: float):
            super().__init__()
            i, j = np.nonzero(np.isfinite(M))
            v = M[i, j]
            self.cells = np.column_stack([j, i]).astype(float)
            self.labels = [f"{x:.1f}" for x in v]
            self.colors = np.where(np.abs(v) > 0.6 * lim, "white", "black")
            self.text = Text(0, 0, "", ha="center", va="center", fontsize=fontsize)
            self.set_in_layout(False)

        def draw(self, renderer):
            if not self.get_visible() or "draw_text" in vars(renderer):
                return  # hidden, or a layout pass (matplotlib's renderer with its drawing turned off)
            t = self.text
            t.set_figure(self.get_figure(root=False))
            t.axes = self.axes
            t.set_transform(self.axes.transData)
            t.set_clip_path(self.get_clip_path())
            for xy, label, color in zip(self.cells, self.labels, self.colors):
                t.set_position(xy)
                t.set_text(label)
                t.set_color(color)
                t.draw(renderer)
            self.stale = False

    return CellValues


def where_figure(stats: dict, *, title: str = "where the model fails", fig=None, alpha: float = 0.01):
    """Per-cell standardised statistics over (layer:neuron) x bins of the model's pre-activation,
    one heatmap per statistic, each bin's value written in it.

    ``stats`` is the output of :func:`gift_theory.lab.where_it_fails`: ``rows`` ("layer:neuron",
    0-based neurons), ``edges`` (the bins' edges on the pre-activation, shared by every row) and
    for each statistic a (rows, bins) array of ``sum z / sqrt(count)``, N(0, 1) under the model.
    Every panel is on one colour scale (they are all z: a 3 reads as a 3 in every panel) and
    the cells beyond the family-wise ``alpha`` threshold over all marked cells (Bonferroni,
    two-sided) are outlined; the kurtosis (:data:`UNMARKED`), whose z is not normal in its tails
    at a few dozen shots, is shown and not marked. An empty bin (no input reaches it) is grey.

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(stats["maps"])
    rows = list(stats["rows"])
    nr = len(rows)
    bins = np.asarray(stats["maps"][names[0]]).shape[1]
    edges = stats.get("edges")
    if fig is None:
        fig = _new_figure((2.6 + 2.7 * len(names), 2.0 + 0.22 * nr))
    # not shared: every panel's image spans the same rows, and only the first names them (a shared
    # axis would make and lay out every row's tick in every panel)
    axes = np.atleast_1d(fig.subplots(1, len(names)))
    font = 7 if nr <= 40 else 5 if nr <= 80 else 0  # values on the bins while they stay legible
    layer_of = [r.split(":")[0] for r in rows]
    breaks = [i - 0.5 for i in range(1, nr) if layer_of[i] != layer_of[i - 1]]
    Ms = {name: np.asarray(stats["maps"][name], float) for name in names}
    marked = [n for n in names if n not in UNMARKED]
    m = sum(int(np.isfinite(Ms[n]).sum()) for n in marked)
    zc = _significance(m, alpha)
    finite = [np.abs(M[np.isfinite(M)]) for M in Ms.values()]
    lim = max([zc + 1.0] + [float(f.max()) for f in finite if f.size])
    cmap = _cmap_with_empty()
    im = None
    for k, (ax, name) in enumerate(zip(axes, names)):
        M = Ms[name]
        im = ax.imshow(np.ma.masked_invalid(M), aspect="auto", cmap=cmap, vmin=-lim, vmax=lim, interpolation="nearest")
        head, _ = WHERE_LABELS.get(name, (name, "z"))
        ax.set_title(head + ("\n(not marked: not normal in its tails)" if name in UNMARKED else ""), fontsize=9)
        if edges is not None:
            ax.set_xticks(np.arange(bins + 1) - 0.5)
            ax.set_xticklabels([f"{e:.2g}" for e in edges], fontsize=6, rotation=60)
            ax.set_xlabel("model's noiseless pre-activation z\n(bin edges; every row the same bins)", fontsize=8)
        else:
            ax.set_xticks(range(bins))
            ax.set_xticklabels([str(b + 1) for b in range(bins)], fontsize=7)
            ax.set_xlabel("bin of the model's pre-activation\n(1 = lowest)", fontsize=8)
        for y in breaks:
            ax.axhline(y, color="k", lw=0.8)
        if name not in UNMARKED:
            _outline(ax, np.nan_to_num(np.abs(M)) > zc)
        if font:
            ax.add_artist(_cell_values_artist()(M, lim, font))
        if k == 0:
            step = max(1, int(np.ceil(nr / 60)))
            ax.set_yticks(range(0, nr, step))
            ax.set_yticklabels(rows[::step], fontsize=7 if nr <= 40 else 5)
            ax.set_ylabel("layer:neuron (neurons from 0)", fontsize=8)
        else:
            ax.set_yticks([])
    cb = fig.colorbar(im, ax=list(axes), shrink=0.9, aspect=40)
    cb.set_label("z (N(0, 1) under the model), one scale for every panel", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    for v in (-zc, zc):
        cb.ax.axhline(v, color="k", lw=1.2)
    fig.suptitle(f"{title}   (each bin: sum of z / sqrt(count) over the inputs in it; outlined: |z| > {zc:.2f}, "
                 f"significant at {alpha:g} family-wise over {m} cells; grey: no input in the bin)", fontsize=9)
    return _root(fig)


def _cmap_with_empty():
    import matplotlib

    return matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.8")


def pit_figure(stats: dict, *, title: str = "calibration of the model's law: PIT of the measured shots", fig=None):
    """Per measured layer, the histogram of the measured shots' randomised PIT among the model's
    shots of their cell (``stats["pit"]`` of :func:`gift_theory.lab.where_it_fails`): flat under
    the model; a U shape means the model's spread is too narrow, a hump too wide, a slope a
    shifted mean. Band: +-2 sd of a bin's share if each cell counted once (a cell's shots share
    the model's draws, so this is the wider, conservative band)."""
    layers = sorted(stats["pit"])
    if fig is None:
        fig = _new_figure((2.2 + 2.6 * len(layers), 3.2))
    axes = np.atleast_1d(fig.subplots(1, len(layers), sharey=True))
    for ax, l in zip(axes, layers):
        counts = np.asarray(stats["pit"][l], float)
        nb = counts.size
        share = counts / max(counts.sum(), 1.0)
        p = 1.0 / nb
        band = 2.0 * np.sqrt(p * (1 - p) / max(stats["pit_cells"][l], 1))
        ax.axhspan(p - band, p + band, color="0.88", label="uniform $\\pm$ 2 sd")
        ax.axhline(p, color="0.4", lw=0.8)
        ax.bar((np.arange(nb) + 0.5) / nb, share, width=1.0 / nb, color="tab:blue", alpha=0.7, edgecolor="k",
               lw=0.4, label="measured shots")
        ax.set_xlim(0, 1)
        ax.set_xlabel("PIT: share of the model's shots below a measured one", fontsize=8)
        ax.set_title(f"layer {l}", fontsize=9)
        ax.legend(fontsize=7, loc="lower center")
    axes[0].set_ylabel("share of the measured shots", fontsize=8)
    fig.suptitle(title + "  (flat: calibrated; U: model too narrow; hump: too wide; slope: mean shifted)", fontsize=9)
    return _root(fig)


def correlation_figure(stats: dict, *, title: str = "correlation between neurons: measured against model",
                       fig=None, alpha: float = 0.01):
    """Per measured layer of two or more neurons, the z of each pair's within-cell correlation
    (measured against the model's, Fisher z over inputs; ``stats["correlation"]``), on one colour
    scale for every panel, the pairs significant at family-wise ``alpha`` over all pairs
    outlined. A shared gain or a common noise shows as a block of one sign."""
    corr = {l: np.asarray(v, float) for l, v in stats["correlation"].items()}
    layers = sorted(corr)
    if fig is None:
        fig = _new_figure((1.8 + 3.2 * max(len(layers), 1), 3.6))
    if not layers:
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no measured layer has two neurons", ha="center", va="center")
        ax.set_axis_off()
        return _root(fig)
    axes = np.atleast_1d(fig.subplots(1, len(layers)))
    m = sum(C.shape[0] * (C.shape[0] - 1) // 2 for C in corr.values())
    zc = _significance(m, alpha)
    lim = max([zc + 1.0] + [float(np.abs(C).max()) for C in corr.values()])
    im = None
    for ax, l in zip(axes, layers):
        C = corr[l]
        im = ax.imshow(C, cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
        _outline(ax, np.triu(np.abs(C) > zc, 1) | np.tril(np.abs(C) > zc, -1), lw=1.0)
        d = C.shape[0]
        step = max(1, int(np.ceil(d / 16)))
        ax.set_xticks(range(0, d, step))
        ax.set_yticks(range(0, d, step))
        ax.tick_params(labelsize=6)
        ax.set_xlabel("neuron", fontsize=8)
        ax.set_ylabel("neuron", fontsize=8)
        ax.set_title(f"layer {l}", fontsize=9)
    cb = fig.colorbar(im, ax=list(axes), shrink=0.9)
    cb.set_label("z of measured - model correlation\n(Fisher z, over inputs)", fontsize=8)
    for v in (-zc, zc):
        cb.ax.axhline(v, color="k", lw=1.2)
    fig.suptitle(f"{title}   (outlined: |z| > {zc:.2f}, significant at {alpha:g} family-wise over {m} pairs)",
                 fontsize=9)
    return _root(fig)


def law_figure(stats: dict, *, title: str = "the noise's law: quantiles of the standardised shots", fig=None):
    """Per measured layer, the quantile-quantile plot of the measured shots standardised by the
    model's cell mean and variance against the model's own shots standardised alike
    (``stats["qq"]``): on the diagonal under the model; tails above it on the right (below on
    the left) are heavier than the model's (a Laplace law), inside it lighter (a uniform law).
    The legend gives both pooled excess kurtoses."""
    qq = stats["qq"]
    layers = sorted(qq)
    if fig is None:
        fig = _new_figure((1.8 + 3.0 * len(layers), 3.6))
    axes = np.atleast_1d(fig.subplots(1, len(layers)))
    for ax, l in zip(axes, layers):
        q = qq[l]
        xm, ym = np.asarray(q["model"], float), np.asarray(q["measured"], float)
        lo, hi = float(min(xm.min(), ym.min())), float(max(xm.max(), ym.max()))
        ax.plot([lo, hi], [lo, hi], color="k", lw=0.8, ls="--", label="the model's law")
        ax.plot(xm, ym, "o-", ms=3, color="tab:red",
                label=f"measured: excess kurtosis {q['kurtosis_measured']:+.2f}\n(model's {q['kurtosis_model']:+.2f})")
        ax.set_xlabel("model's quantile (standardised shot)", fontsize=8)
        ax.set_title(f"layer {l}", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3, lw=0.5)
    axes[0].set_ylabel("measured quantile (standardised shot)", fontsize=8)
    fig.suptitle(title + "  (above the diagonal on the right: heavier tails than the model's)", fontsize=9)
    return _root(fig)


def ppc_figure(pred, layer: int, *, fig=None, max_neurons: int = 16, title: str | None = None):
    """Posterior-predictive overlay of one layer, neuron by neuron (ArviZ's ``plot_ppc``): the
    measured shots' density pooled over the inputs (black) against the model's, each replicate
    of r shots per input a thin line and their mean a thick one, for one or several models
    (a :class:`~gift_theory.lab._compare.PredictiveShots` or a sequence of them, same inputs).

    Returns
    -------
    matplotlib.figure.Figure
    """
    plist = [pred] if hasattr(pred, "layer_ids") else list(pred)
    li = list(plist[0].layer_ids).index(layer)
    Y = np.asarray(plist[0].measured[li], float)
    n, r, d = Y.shape
    show = min(d, max_neurons)
    cols = min(show, 4)
    rws = int(np.ceil(show / cols))
    if fig is None:
        fig = _new_figure((2.4 * cols + 0.6, 2.0 * rws + 0.9))
    axes = np.atleast_1d(fig.subplots(rws, cols, squeeze=False)).ravel()
    colors = _COLORS[1:] if len(plist) == 1 else _COLORS
    for j in range(show):
        ax = axes[j]
        vals = [Y[:, :, j].ravel()] + [np.asarray(p.model[li], float)[:, :, j].ravel() for p in plist]
        lo, hi = min(float(v.min()) for v in vals), max(float(v.max()) for v in vals)
        edges = np.linspace(lo, hi, 31)
        centres = 0.5 * (edges[1:] + edges[:-1])
        for c, p in zip(colors, plist):
            M = np.asarray(p.model[li], float)[:, :, j]
            reps = max(M.shape[1] // r, 1)
            dens = np.array([np.histogram(M[:, g * r:(g + 1) * r].ravel(), edges, density=True)[0] for g in range(reps)])
            for dd in dens:
                ax.plot(centres, dd, color=c, lw=0.5, alpha=0.5)
            ax.plot(centres, dens.mean(0), color=c, lw=1.6, label=f"{p.label} ({reps} x {r} shots)")
        ax.stairs(np.histogram(Y[:, :, j].ravel(), edges, density=True)[0], edges, color="k", lw=1.3,
                  label=f"measured ({r} shots)")
        ax.set_title(f"neuron {layer}:{j}", fontsize=8)
        ax.tick_params(labelsize=6)
        ax.set_yticks([])  # the densities' shapes are compared, not their heights (as ArviZ's plot_ppc)
        if j % cols == 0:
            ax.set_ylabel("density over the inputs", fontsize=7)
        if j >= show - cols:
            ax.set_xlabel("value", fontsize=7)
    for ax in axes[show:]:
        ax.set_axis_off()
    axes[0].legend(fontsize=6, loc="upper right")
    more = f"; first {show} of {d} neurons" if show < d else ""
    fig.suptitle(title or f"layer {layer}: measured shots against the model's, pooled over {n} inputs{more}",
                 fontsize=9)
    return _root(fig)


def comparison_table(named: list, best: int = 0, replicates: int | None = None) -> list[dict]:
    """The rows of a model comparison (ArviZ's ``compare``): ``named`` is a list of (name,
    :class:`~gift_theory.lab._compare.Comparison`, status) on the same inputs; each row has the
    discrepancy and its sd under the model, the difference to the model ``best`` (index) and its
    paired bootstrap standard error over inputs (:func:`~gift_theory.lab._compare.discrepancy_difference`)."""
    from ._compare import DIFFERENCE_REPLICATES, discrepancy_difference

    ref = named[best][1]
    out = []
    for name, c, status in named:
        delta, se = discrepancy_difference(c, ref, replicates or DIFFERENCE_REPLICATES)
        out.append({"model": name, "status": status, "discrepancy": float(c.discrepancy), "sd": float(c.se),
                    "delta": delta, "delta_se": se, "p_value": float(c.p_value)})
    return out


def comparison_figure(table: list, noise_floor: float, floor_se: float, *, title: str = "model comparison",
                      fig=None):
    """The model comparison of :func:`comparison_table`, as a plot and a table: each model's
    held-out discrepancy (+-2 sd under the model) against the noise floor band, its difference
    to the first row with +-2 paired standard errors, and the numbers."""
    if fig is None:
        fig = _new_figure((12.0, 2.2 + 0.4 * len(table)))
    ax, tx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.35]})
    y = np.arange(len(table))[::-1]
    d = np.array([t["discrepancy"] for t in table])
    sd = np.array([t["sd"] for t in table])
    delta = np.array([t["delta"] for t in table])
    dse = np.array([t["delta_se"] for t in table])
    ax.axvspan(noise_floor - 2 * floor_se, noise_floor + 2 * floor_se, color="0.88", label="noise floor $\\pm$ 2 se")
    colors = ["tab:red" if t["p_value"] < 0.01 else "tab:green" for t in table]
    ax.errorbar(d, y, xerr=2 * sd, fmt="none", ecolor="k", capsize=3, label="discrepancy $\\pm$ 2 sd")
    ax.scatter(d, y, c=colors, zorder=3, s=30)
    ok = np.isfinite(dse)
    ref = d[0]
    ax.errorbar(ref + delta[ok][1:], y[ok][1:] - 0.25, xerr=2 * dse[ok][1:], fmt="v", color="0.45", ms=4, capsize=2,
                label=f"difference to {table[0]['model']}\n$\\pm$ 2 paired se (drawn from its point)")
    ax.set_yticks(y)
    ax.set_yticklabels([t["model"] for t in table], fontsize=7)
    from matplotlib.ticker import FuncFormatter

    ax.set_xscale("symlog", linthresh=max(10.0, 4 * float(np.nanmax(sd))))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xlabel("held-out discrepancy, symlog axis (lower is better; red: rejected at 0.01)", fontsize=8)
    ax.set_ylim(-0.7, len(table) - 0.4)
    ax.grid(alpha=0.3, lw=0.5, axis="x")
    tx.set_axis_off()
    tx.legend(*ax.get_legend_handles_labels(), fontsize=7, loc="lower center", ncol=3)  # beside the table: no point under it
    cells = [[t["status"] or "", f"{t['discrepancy']:.4g} +- {t['sd']:.2g}",
              ("" if i == 0 else f"{t['delta']:+.4g} +- {t['delta_se']:.2g}"), f"{t['p_value']:.3g}"]
             for i, t in enumerate(table)]
    tab = tx.table(cellText=cells, rowLabels=[t["model"] for t in table],
                   colLabels=["status", "discrepancy\n+- sd", f"minus the first\n+- paired se", "p"],
                   loc="center", cellLoc="right", colWidths=[0.14, 0.22, 0.24, 0.14])
    tab.auto_set_font_size(False)
    tab.set_fontsize(7)
    tab.scale(1.0, 1.35)
    for (i, _), cell in tab.get_celld().items():
        if i == 0:
            cell.set_height(cell.get_height() * 1.8)
    fig.suptitle(f"{title}   (floor {noise_floor:.4g} +- {floor_se:.2g}; a difference whose +-2 se covers 0 does "
                 f"not tell the two apart on these inputs)", fontsize=9)
    return _root(fig)


def pairs_figure(joint: dict, *, title: str = "fitted parameters and their joint 95 % region", fig=None,
                 points: int = 200):
    """Pair plot of the moment-fitted parameters (``joint`` of
    :func:`~gift_theory.lab._intervals.moment_intervals`): on the diagonal each parameter's
    sampling density with its 95 % interval shaded, below it each pair's joint 95 % region (the
    sandwich covariance's ellipse on the fit scale, log for a positive parameter, mapped back)
    (Hotelling's, at the replicates' degrees of freedom) with the fitted values and both marginal
    intervals (Student t: the intervals ``gift fit`` reports); above it the pair's correlation. Two
    parameters that trade off (shot noise and the additive level without taps) show as a long
    tilted region whose marginal intervals say little."""
    from scipy import stats as st

    names = list(joint["params"])
    k = len(names)
    cov = np.asarray(joint["cov"], float)
    centre = np.asarray(joint["centre"], float)
    logs = [sc == "log" for sc in joint["scale"]]
    level = float(joint.get("level", 0.95))
    back = [(np.exp if lg else (lambda v: v)) for lg in logs]
    if fig is None:
        fig = _new_figure((1.2 + 2.4 * k, 0.9 + 2.3 * k))
    axes = np.atleast_2d(fig.subplots(k, k, squeeze=False))
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    dof = int(joint.get("dof", 0)) or 10 ** 6
    # the intervals' own quantile (Student t at the replicates' degrees of freedom) and, for two
    # parameters, Hotelling's: the region the same estimated covariance gives
    qm = st.t.ppf(0.5 + level / 2, dof)
    r2 = np.sqrt(2.0 * dof / max(dof - 1, 1) * st.f.isf(1 - level, 2, max(dof - 1, 1)))
    corr = cov / np.maximum(np.outer(sd, sd), 1e-300)
    for i in range(k):
        for j in range(k):
            ax = axes[i, j]
            if i == j:
                t = centre[i] + sd[i] * np.linspace(-4, 4, points)
                dens = st.norm.pdf(t, centre[i], max(sd[i], 1e-300))
                x = back[i](t)
                ax.plot(x, dens / np.max(dens), color="tab:blue")
                inside = np.abs(t - centre[i]) <= qm * sd[i]
                ax.fill_between(x, 0, dens / np.max(dens), where=inside, color="tab:blue", alpha=0.25,
                                label=f"{level:.0%}: [{back[i](centre[i] - qm * sd[i]):.3g}, "
                                      f"{back[i](centre[i] + qm * sd[i]):.3g}]")
                ax.axvline(joint["estimate"][i], color="k", lw=0.8)
                ax.set_yticks([])
                ax.legend(fontsize=6, loc="upper right")
            elif i > j:
                a = np.linspace(0, 2 * np.pi, points)
                C2 = cov[np.ix_([j, i], [j, i])]
                w, V = np.linalg.eigh(0.5 * (C2 + C2.T))
                ell = (V * np.sqrt(np.maximum(w, 0.0))) @ np.stack([np.cos(a), np.sin(a)]) * r2
                ax.fill(back[j](centre[j] + ell[0]), back[i](centre[i] + ell[1]), color="tab:blue", alpha=0.25,
                        label=f"joint {level:.0%}")
                ax.plot(joint["estimate"][j], joint["estimate"][i], "k+", ms=9, label="the fitted values")
                ax.plot(back[j](centre[j] + np.array([-1, 1]) * qm * sd[j]), [back[i](centre[i])] * 2, color="k", lw=0.8,
                        label=f"marginal {level:.0%} intervals\n(around the bias-corrected centre)")
                ax.plot([back[j](centre[j])] * 2, back[i](centre[i] + np.array([-1, 1]) * qm * sd[i]), color="k", lw=0.8)
                if i == k - 1 and j == 0:  # in the empty corner: never over the region
                    axes[0, k - 1].legend(*ax.get_legend_handles_labels(), fontsize=7, loc="lower center")
            else:
                ax.text(0.5, 0.75, f"correlation of\n{names[j]} and {names[i]}\n{corr[i, j]:+.2f}", ha="center",
                        va="center", fontsize=9, transform=ax.transAxes)
                ax.set_axis_off()
            if i == k - 1:
                ax.set_xlabel(names[j], fontsize=8)
            if j == 0 and i > 0:
                ax.set_ylabel(names[i], fontsize=8)
            from matplotlib.ticker import MaxNLocator

            ax.xaxis.set_major_locator(MaxNLocator(4))
            if i != j:
                ax.yaxis.set_major_locator(MaxNLocator(4))
            ax.tick_params(labelsize=6)
    fig.suptitle(title + f"  (sandwich covariance of the moment fit, {joint.get('dof', 0) + 1} parametric replicates)",
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
        _points_with_bars(a_mean, mu, Y, 2 * np.sqrt(V / r), c, m.label)
        _points_with_bars(a_var, v, V, 2 * V * np.sqrt(2.0 / (r - 1)), c, m.label)
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
    # the identity panels' points lie along the diagonal: their legend goes to the corner on the side
    # fewer points are (matplotlib's "best" would test every error bar of thousands against each spot)
    corner = {a_mean: _empty_corner(Y, [m.model_mean[li].ravel() for m in mlist]),
              a_var: _empty_corner(V, [m.model_var[li].ravel() for m in mlist])}
    for ax in (a_mean, a_var, a_rz, a_rv):
        ax.legend(fontsize=7, loc=corner.get(ax, "best"), markerscale=2)
        ax.grid(alpha=0.3, lw=0.5)
    kind = "output" if layer == max(mlist[0].layer_ids) else "tap"
    fig.suptitle(title or f"layer {layer} ({kind}, {d} neurons): measured against model, {n} inputs x {r} shots "
                          f"(model: {mlist[0].K} shots)", fontsize=10)
    return _root(fig)


def _points_with_bars(ax, x, y, err, color, label: str) -> None:
    """Points (x, y) with vertical bars y +- err: the bars one line broken between them (a NaN
    after each), not matplotlib's ``errorbar`` (a path per bar, each transformed on its own: on log
    axes, thousands of bars cost a second per figure); the legend shows the point."""
    x, y, err = (np.ravel(np.asarray(a, float)) for a in (x, y, err))
    gap = np.full_like(x, np.nan)
    ax.plot(np.column_stack([x, x, gap]).ravel(), np.column_stack([y - err, y + err, gap]).ravel(), color=color,
            lw=0.4, alpha=0.5)
    ax.plot(x, y, "o", ms=2.5, color=color, alpha=0.5, label=label)


def _empty_corner(measured, models) -> str:
    """Where a legend covers fewest points of a measured-against-model panel: upper left (above
    the diagonal) when most points are below it, else lower right."""
    above = sum(int(np.sum(measured > m)) for m in models)
    return "upper left" if 2 * above <= len(models) * np.size(measured) else "lower right"


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
