"""Ours: relative accuracy gain against the baseline accuracy, one point per cell and method.

Not a paper figure. The paper's "up to 28 % relative accuracy improvement" can only occur where
the baseline (w0 on the chip) is low: a gain of 28 % needs a baseline below 1 / 1.28 = 0.78.
Each point is one (s0, st) cell of one method: x the mean baseline accuracy over seeds, y the
mean relative accuracy gain 100 (A_after - A_before) / A_before with its 95 % Student-t
interval over seeds; the horizontal line is the paper's 28 %, the dotted curve the largest
gain possible at each baseline (100 (1 / A - 1)). Left: training data; right: test data.

Methods: GIFT on the deeper net (the paper grid and the extended st where the baseline
collapses), the variants at the key cells (gift without confirmation or with a 5x budget,
gift-printed with and without w0 at several eta, the retrain oracle and its s0 control), the
rivals on the deeper net at the extended st; and, when saved, GIFT on the shallower net, the
shallower net's rivals, and the ceiling of the GIFT line (the referee's best step along the
pathwise and the printed direction, chosen on training data).
Data: sweeps ``gift_awgn_deep``, ``gift_regime``, ``variants``, ``rivals_regime``
(optional: ``gift_awgn_shallow``, ``rivals``, ``ceiling_deep``, ``ceiling_shallow``).
Run: ``python -m paper_figures.gain_vs_baseline --scale paper``.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from ._plot import improvements, mean_ci

NAME = "gain_vs_baseline"
LABEL = "ours:gain_vs_baseline"
SWEEPS = ("gift_awgn_deep", "gift_regime", "variants", "rivals_regime")
OPTIONAL = ("gift_awgn_shallow", "rivals", "ceiling_deep", "ceiling_shallow")
PAPER_PCT = 28.0


def ceiling_as_finetune(ds: xr.Dataset, kind: str) -> xr.Dataset:
    """A ceiling sweep as a fine-tuning sweep along direction ``kind``: "after" is the referee's
    best step along the line (accuracy: the step of the highest training accuracy; loss: the
    step of the lowest training loss), on training and test data."""
    return xr.Dataset({
        "loss_before": ds["loss_before"], "loss_after": ds[f"{kind}_loss"],
        "accuracy_before": ds["accuracy_before"], "accuracy_after": ds[f"{kind}_accuracy_best"],
        "test_loss_before": ds["test_loss_before"], "test_loss_after": ds[f"{kind}_test_loss"],
        "test_accuracy_before": ds["test_accuracy_before"], "test_accuracy_after": ds[f"{kind}_test_accuracy_at_best"],
    }, attrs=ds.attrs)


def cell_points(ds: xr.Dataset, split: str) -> list[dict]:
    """One record per (s0, st) cell with data: baseline mean, gain mean and its 95 % half-width."""
    p = "" if split == "train" else "test_"
    imp = improvements(ds, split)
    m, h = mean_ci(imp["acc_pct"])
    base = ds[f"{p}accuracy_before"].mean("seed")
    out = []
    for s0 in ds["s0"].values:
        for st in ds["st"].values:
            g = float(m.sel(s0=s0, st=st))
            if np.isfinite(g):
                out.append({"s0": float(s0), "st": float(st), "baseline": float(base.sel(s0=s0, st=st)),
                            "gain_pct": g, "ci95": float(h.sel(s0=s0, st=st))})
    return out


def series(data: dict) -> dict[str, list[tuple[xr.Dataset, str]]]:
    """label -> fine-tuning datasets (dims s0, st, seed) from every sweep present in ``data``."""
    out: dict[str, list] = {}

    def add(label, ds):
        out.setdefault(label, []).append(ds)

    for name, label in (("gift_awgn_deep", "gift (deep)"), ("gift_regime", "gift (deep)"),
                        ("gift_awgn_shallow", "gift (shallow)")):
        if name in data:
            add(label, data[name])
    if "variants" in data:
        for v in data["variants"]["variant"].values:
            add(f"{v} (deep)", data["variants"].sel(variant=v, drop=True))
    for name, net in (("rivals_regime", "deep"), ("rivals", "shallow")):
        if name in data:
            for mth in data[name]["method"].values:
                add(f"{mth} (deep)" if mth == "gift" and net == "deep" else f"{mth} ({net})",
                    data[name].sel({"method": mth}, drop=True))
    for name, net in (("ceiling_deep", "deep"), ("ceiling_shallow", "shallow")):
        if name in data:
            for kind in ("pathwise", "score_paper", "gradient"):
                if f"{kind}_accuracy_best" in data[name]:
                    add(f"ceiling {kind} ({net})", ceiling_as_finetune(data[name], kind))
    return out


def draw(data: dict, ax=None):
    """Two panels (training, test data); ``ax``: two axes to draw into. Returns the Figure."""
    if ax is None:
        fig, axes = plt.subplots(1, 2, figsize=(17, 5.5), sharey=True)  # room for a two-column legend
    else:
        axes = list(ax)
        fig = axes[0].figure
    ser = series(data)
    markers = "osD^v<>pPX*hH8d"
    cmap = plt.get_cmap("tab20")
    ys = [0.0]
    for a, split in zip(axes, ("train", "test")):
        seen_rows = {}
        for k, (label, parts) in enumerate(ser.items()):
            pts = []
            for ds in parts:
                # a cell present in two sweeps (gift at one cell of both grids) is one point
                for r in cell_points(ds, split):
                    key = (label, r["s0"], r["st"])
                    if key not in seen_rows:
                        seen_rows[key] = r
                        pts.append(r)
            if not pts:
                continue
            x = [r["baseline"] for r in pts]
            y = [r["gain_pct"] for r in pts]
            e = [r["ci95"] if np.isfinite(r["ci95"]) else 0.0 for r in pts]
            ys += [v + d for v, d in zip(y, e)] + [v - d for v, d in zip(y, e)]  # the limits hold the intervals
            ceiling = label.startswith("ceiling")
            a.errorbar(x, y, yerr=e, fmt=markers[k % len(markers)], ms=4 if not ceiling else 6, capsize=2,
                       color=cmap(k % 20), mfc="none" if ceiling else None, lw=0.8, label=label)
        a.axhline(PAPER_PCT, color="crimson", ls="--", lw=1.2, label="paper: 28 %")
        a.axhline(0, color="grey", lw=0.8)
        xs = np.linspace(0.1, 1.0, 200)
        a.plot(xs, 100 * (1 / xs - 1), ":", color="black", lw=0.8, label="largest possible: 100 (1/A - 1)")
        a.set_xlabel(f"baseline accuracy of w0 on the chip ({'training' if split == 'train' else 'test'} data)")
        a.set_xlim(0.0, 1.0)
        a.set_title(f"{'training' if split == 'train' else 'test'} data", fontsize=9)
    axes[0].set_ylim(max(min(ys) - 5, -100), max(max(ys) + 10, PAPER_PCT + 15))
    axes[0].set_ylabel("relative accuracy gain, % (mean over seeds, 95 % CI)")
    n_labels = len(axes[-1].get_legend_handles_labels()[1])
    axes[-1].legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), ncol=1 if n_labels <= 24 else 2)
    fig.suptitle("relative accuracy gain against baseline accuracy, one point per (s0, st) cell and method; "
                 "28 % needs a baseline below 0.78", fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
