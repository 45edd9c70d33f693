"""Drawing helpers shared by the figure scripts (data in, figure out; the backend is chosen by
the caller: ``paper_figures.build`` uses ``agg``).

Improvements follow the paper's Section "Simulation study": relative improvement of the loss
``100 (L_before - L_after) / L_before`` and of the accuracy ``100 (A_after - A_before) /
A_before``; absolute improvements are ``L_before - L_after`` and ``A_after - A_before`` (in
percentage points). Means are over seeds; 95 % confidence intervals are Student-t intervals
over seeds (none with a single seed).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from scipy import stats


def improvements(ds: xr.Dataset, split: str = "train") -> xr.Dataset:
    """Relative and absolute improvements per point.

    Parameters
    ----------
    ds : a fine-tuning sweep (reference §4 keys as data variables)
    split : "train" (the in-situ Eval on training data) or "test"

    Returns
    -------
    Dataset with ``loss_pct``, ``acc_pct`` (relative, %), ``loss_abs`` and ``acc_abs``
    (accuracy in percentage points), same dims as ``ds``.
    """
    p = "" if split == "train" else "test_"
    lb, la = ds[f"{p}loss_before"], ds[f"{p}loss_after"]
    ab, aa = ds[f"{p}accuracy_before"], ds[f"{p}accuracy_after"]
    return xr.Dataset({"loss_pct": 100.0 * (lb - la) / lb, "acc_pct": 100.0 * (aa - ab) / ab,
                       "loss_abs": lb - la, "acc_abs": 100.0 * (aa - ab)})


def mean_ci(da: xr.DataArray, dim: str = "seed", level: float = 0.95):
    """Mean over ``dim`` and the half-width of its Student-t confidence interval (NaN if n < 2)."""
    n = da.count(dim)
    mean = da.mean(dim)
    sd = da.std(dim, ddof=1) if da.sizes[dim] > 1 else xr.full_like(mean, np.nan)
    q = xr.apply_ufunc(lambda k: stats.t.ppf(0.5 + level / 2, np.maximum(k - 1, 1)), n)
    half = xr.where(n > 1, q * sd / np.sqrt(n), np.nan)
    return mean, half


def interval_colour(mean, half):
    """The value a cell is coloured by: the end of its 95 % interval nearest to 0, 0 when the
    interval contains 0 (a cell whose gain is not distinguishable from none is neutral);
    the mean where there is no interval (one seed)."""
    m = np.asarray(mean, float)
    if half is None:
        return m
    h = np.asarray(half, float)
    shrunk = np.sign(m) * np.maximum(np.abs(m) - np.where(np.isfinite(h), h, 0.0), 0.0)
    return np.where(np.isfinite(m), shrunk, np.nan)


def heatmap(ax, mean: xr.DataArray, half: xr.DataArray | None, title: str, unit: str = "%", cmap: str = "RdYlGn",
            notes: dict | None = None):
    """Heatmap of ``mean`` over (s0 rows, st columns), cells annotated with mean and ± 95 % CI.

    The colour is the interval's end nearest to 0 (:func:`interval_colour`: neutral when the
    interval contains 0), on a scale symmetric about 0 (green = improvement). Cells with
    s0 = st are outlined: there the model is correctly specified. ``notes``: (s0, st) -> extra
    text under a cell's numbers (e.g. its baseline and retrain-oracle accuracy).
    """
    m = mean.transpose("s0", "st")
    vals = np.asarray(m.values, float)
    h = None if half is None else np.asarray(half.transpose("s0", "st").values, float)
    colour = interval_colour(vals, h)
    lim = np.nanmax(np.abs(vals)) if np.isfinite(vals).any() else 1.0
    lim = lim if lim > 0 else 1.0
    im = ax.imshow(colour, cmap=cmap, vmin=-lim, vmax=lim, origin="lower", aspect="auto")
    s0s, sts = list(m["s0"].values), list(m["st"].values)
    ax.set_xticks(range(len(sts)), [f"{v:g}" for v in sts])
    ax.set_yticks(range(len(s0s)), [f"{v:g}" for v in s0s])
    ax.set_xlabel(r"true noise $s_t$")
    ax.set_ylabel(r"training noise $s_0$")
    ax.set_title(title, fontsize=9)
    for i in range(len(s0s)):
        for j in range(len(sts)):
            v = vals[i, j]
            if not np.isfinite(v):
                ax.text(j, i, "n/a", ha="center", va="center", fontsize=7, color="grey")
                continue
            txt = f"{v:.2f}{unit}" if abs(v) < 10 else f"{v:.1f}{unit}"
            if h is not None and np.isfinite(h[i, j]):
                txt += f"\n±{h[i, j]:.2f}"
            note = (notes or {}).get((round(float(s0s[i]), 12), round(float(sts[j]), 12)))
            if note:
                txt += "\n" + note
            ax.text(j, i, txt, ha="center", va="center", fontsize=6 if note else 7)
            if np.isclose(s0s[i], sts[j]):
                ax.add_patch(plt.Rectangle((j - 0.45, i - 0.45), 0.9, 0.9, fill=False, lw=2, ec="navy", ls="--"))
    plt.colorbar(im, ax=ax, shrink=0.8)
    return im


def grid_note(ds: xr.Dataset) -> str:
    """One line naming what a sweep covered: points done, seeds, nets, data set."""
    import json

    fixed = json.loads(ds.attrs.get("fixed_json", "{}"))
    seeds = ds.sizes.get("seed", 1)
    parts = [f"{int(ds.attrs.get('points_done', 0))}/{int(ds.attrs.get('points_total', 0))} points",
             f"{seeds} seed{'s' if seeds != 1 else ''}"]
    if "dataset" in fixed:
        parts.append(f"data {fixed['dataset']}")
    if "arch" in fixed:
        parts.append(f"net {fixed['arch']}")
    return ", ".join(parts)


def cell_notes(ds: xr.Dataset, split: str = "train", oracle=()) -> dict:
    """(s0, st) -> "base A" (mean accuracy of w0 over seeds) and, where one of ``oracle`` (sweeps
    of the retrain oracle with dims s0, st, seed) has the cell, a second line "oracle B" (its
    mean accuracy)."""
    p = "" if split == "train" else "test_"
    base = ds[f"{p}accuracy_before"].mean("seed")
    notes = {}
    for s0 in ds["s0"].values:
        for st in ds["st"].values:
            b = float(base.sel(s0=s0, st=st))
            if not np.isfinite(b):
                continue
            txt = f"base {b:.2f}"
            for orc in oracle or ():
                if s0 in orc["s0"].values and st in orc["st"].values:
                    o = float(orc[f"{p}accuracy_after"].sel(s0=s0, st=st).mean("seed"))
                    if np.isfinite(o):
                        txt += f"\noracle {o:.2f}"  # its own line: "base A, oracle B" ran over the cell's edges
                        break
            notes[(round(float(s0), 12), round(float(st), 12))] = txt
    return notes


def retrain_oracle(data: dict, net: str = "deep") -> list:
    """The retrain oracle's points of ``net`` (datasets with dims s0, st, seed) from the sweeps in
    ``data``: the variants sweep (deeper net) and the rivals sweeps (rivals: shallower net;
    rivals_regime: deeper); empty when none has it."""
    parts = []
    if net == "deep" and "variants" in data and "retrain" in data["variants"]["variant"].values:
        parts.append(data["variants"].sel(variant="retrain", drop=True))
    for name, n in (("rivals", "shallow"), ("rivals_regime", "deep")):
        if n == net and name in data and "retrain" in data[name]["method"].values:
            parts.append(data[name].sel({"method": "retrain"}, drop=True))
    return parts


def improvement_heatmaps(ds: xr.Dataset, split: str, kind: str, title: str, notes: dict | None = None, ax=None):
    """The two-panel figure of fig:performance_gift and relatives: loss and accuracy.

    ``notes``: per-cell text (:func:`cell_notes`); ``ax``: two axes to draw into (default a
    new figure). Returns the Figure."""
    imp = improvements(ds, split)
    if ax is None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.6 if notes else 4))
    else:
        axes = list(ax)
        fig = axes[0].figure
    if kind == "pct":
        panels = [("loss_pct", "loss (MSE) improvement, %", "%"), ("acc_pct", "accuracy improvement, %", "%")]
    else:
        panels = [("loss_abs", "loss (MSE) improvement, absolute", ""),
                  ("acc_abs", "accuracy improvement, percentage points", "")]
    for a, (var, t, unit) in zip(axes, panels):
        mean, half = mean_ci(imp[var])
        heatmap(a, mean, half, t, unit=unit, notes=notes)
    fig.suptitle(f"{title}\n{grid_note(ds)}; mean over seeds, ±95 % CI;\ncolour: the interval's end nearest 0 "
                 f"(neutral if it contains 0); dashed box: $s_0 = s_t$", fontsize=9)
    fig.tight_layout()
    return fig
