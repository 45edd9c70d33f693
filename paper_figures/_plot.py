"""Drawing helpers shared by the figure scripts (matplotlib ``agg``; data in, figure out).

Improvements follow the paper's Section "Simulation study": relative improvement of the loss
``100 (L_before - L_after) / L_before`` and of the accuracy ``100 (A_after - A_before) /
A_before``; absolute improvements are ``L_before - L_after`` and ``A_after - A_before`` (in
percentage points). Means are over seeds; 95 % confidence intervals are Student-t intervals
over seeds (none with a single seed).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from scipy import stats  # noqa: E402


def improvements(ds: xr.Dataset, split: str = "train") -> xr.Dataset:
    """Relative and absolute improvements per point.

    Parameters
    ----------
    ds : a fine-tuning sweep (CONTRACTS §4 keys as data variables)
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


def heatmap(ax, mean: xr.DataArray, half: xr.DataArray | None, title: str, unit: str = "%", cmap: str = "RdYlGn"):
    """Heatmap of ``mean`` over (s0 rows, st columns), cells annotated with mean and ± 95 % CI.

    The colour scale is symmetric about 0 (green = improvement). Cells with s0 = st are
    outlined: there the model is correctly specified.
    """
    m = mean.transpose("s0", "st")
    vals = np.asarray(m.values, float)
    lim = np.nanmax(np.abs(vals)) if np.isfinite(vals).any() else 1.0
    lim = lim if lim > 0 else 1.0
    im = ax.imshow(vals, cmap=cmap, vmin=-lim, vmax=lim, origin="lower", aspect="auto")
    s0s, sts = list(m["s0"].values), list(m["st"].values)
    ax.set_xticks(range(len(sts)), [f"{v:g}" for v in sts])
    ax.set_yticks(range(len(s0s)), [f"{v:g}" for v in s0s])
    ax.set_xlabel(r"true noise $s_t$")
    ax.set_ylabel(r"training noise $s_0$")
    ax.set_title(title, fontsize=9)
    h = None if half is None else np.asarray(half.transpose("s0", "st").values, float)
    for i in range(len(s0s)):
        for j in range(len(sts)):
            v = vals[i, j]
            if not np.isfinite(v):
                ax.text(j, i, "n/a", ha="center", va="center", fontsize=7, color="grey")
                continue
            txt = f"{v:.2f}{unit}" if abs(v) < 10 else f"{v:.1f}{unit}"
            if h is not None and np.isfinite(h[i, j]):
                txt += f"\n±{h[i, j]:.2f}"
            ax.text(j, i, txt, ha="center", va="center", fontsize=7)
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


def improvement_heatmaps(ds: xr.Dataset, split: str, kind: str, title: str):
    """The two-panel figure of fig:performance_gift and relatives: loss and accuracy."""
    imp = improvements(ds, split)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    if kind == "pct":
        panels = [("loss_pct", "loss (MSE) improvement, %", "%"), ("acc_pct", "accuracy improvement, %", "%")]
    else:
        panels = [("loss_abs", "loss (MSE) improvement, absolute", ""),
                  ("acc_abs", "accuracy improvement, percentage points", "")]
    for ax, (var, t, unit) in zip(axes, panels):
        mean, half = mean_ci(imp[var])
        heatmap(ax, mean, half, t, unit=unit)
    fig.suptitle(f"{title}\n{grid_note(ds)}; mean over seeds, ±95 % CI; dashed box: $s_0 = s_t$", fontsize=9)
    fig.tight_layout()
    return fig
