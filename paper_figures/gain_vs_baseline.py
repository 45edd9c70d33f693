"""Ours: accuracy gain against the baseline accuracy, one point per (s0, st) cell and method,
relative (%) and absolute (accuracy points), one column per method family.

Not a paper figure. The paper's "up to 28 % relative accuracy improvement" can only occur where
the baseline (w0 on the chip) is low: a gain of 28 % needs a baseline below 1 / 1.28 = 0.78, and
near a chance baseline (0.1) two accuracy points are already 20 % relative. So each gain is shown
twice: top row relative, 100 (A_after - A_before) / A_before; bottom row absolute, 100 (A_after -
A_before) accuracy points. x is the mean baseline accuracy over seeds, the marker the mean gain
over seeds, the thin bar the seeds' range (its top is the best single run). The dashed line is
28 (% or points), the dotted curve the largest gain possible at each baseline (100 (1/A - 1) and
100 (1 - A)). Training data (where the claims are judged; the test data are in the heatmaps).

Columns (deeper net filled, shallower net hollow): GIFT and the ceiling of its line (the
referee's best step along it); Algorithm 1 as printed (the printed D^[0], the pathwise
direction, the step eta, with and without w0 among its candidates, and the printed line's
ceiling); the other in-situ methods (ift, gradient, random, spsa, physics-aware training,
identify-retrain); retraining in silico without the chip (the oracle at st and its control at
s0). Cells: our grid (s0, st in {0.02, ..., 0.2}), its extension to st = 0.4 and to s0 = 0.01,
st = 0.8, wherever a sweep ran the method.
Data: sweeps ``gift_awgn_deep``, ``gift_regime``, ``variants``, ``rivals_regime``
(optional: ``gift_awgn_shallow``, ``rivals``, ``ceiling_deep``, ``ceiling_shallow``,
``extended``, ``ceiling_extended``).
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
OPTIONAL = ("gift_awgn_shallow", "rivals", "ceiling_deep", "ceiling_shallow", "extended", "ceiling_extended")
PAPER_PCT = 28.0

#: the columns: family title -> methods in it, each (name, colour, marker); GIFT and its ceiling
#: first and strongest
FAMILIES = (
    ("GIFT and the ceiling of its line", (
        ("gift", "tab:blue", "o"), ("ceiling pathwise", "tab:orange", "s"), ("gift-noconfirm", "tab:cyan", "^"),
        ("gift-budget100", "tab:purple", "v"))),
    ("Algorithm 1 as printed", (
        ("gift-printed", "tab:red", "o"), ("pathwise", "tab:brown", "s"), ("ceiling score_paper", "tab:orange", "D"),
        *((f"printed-eta{e}", c, "v") for e, c in (("0.05", "#9ecae1"), ("0.1", "#4292c6"), ("0.3", "#08519c"),
                                                    ("1", "#08306b"))),
        *((f"printed-w0-eta{e}", c, "^") for e, c in (("0.05", "#a1d99b"), ("0.1", "#41ab5d"), ("0.3", "#006d2c"),
                                                       ("1", "#00441b"))))),
    ("other in-situ methods", (
        ("pat", "tab:green", "o"), ("identify-retrain", "tab:red", "s"), ("ift", "tab:olive", "D"),
        ("spsa", "tab:purple", "v"), ("gradient", "tab:grey", "^"), ("random", "black", "x"))),
    ("retraining in silico, no chip", (
        ("retrain", "tab:pink", "o"), ("retrain-s0", "tab:brown", "s"))),
)
LABELS = {"gift": "GIFT", "ceiling pathwise": "ceiling of GIFT's line", "gift-noconfirm": "GIFT without confirmation",
          "gift-budget100": "GIFT, chip budget 100", "gift-printed": "printed D^[0]",
          "pathwise": "pathwise direction", "ceiling score_paper": "ceiling of the D^[0] line",
          "pat": "physics-aware training", "retrain": "retrain at st (oracle)", "retrain-s0": "retrain at s0 (control)"}


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
    """One record per (s0, st) cell with data: ``baseline`` (mean accuracy of w0), the mean
    relative gain ``gain_pct`` with its 95 % half-width ``ci95`` and the seeds' range
    (``pct_min``, ``pct_max``: the best single run), and the same in accuracy points
    (``gain_abs``, ``abs_ci95``, ``abs_min``, ``abs_max``)."""
    p = "" if split == "train" else "test_"
    imp = improvements(ds, split)
    m, h = mean_ci(imp["acc_pct"])
    ma, ha = mean_ci(imp["acc_abs"])
    lo, hi = imp["acc_pct"].min("seed"), imp["acc_pct"].max("seed")
    alo, ahi = imp["acc_abs"].min("seed"), imp["acc_abs"].max("seed")
    base = ds[f"{p}accuracy_before"].mean("seed")
    out = []
    for s0 in ds["s0"].values:
        for st in ds["st"].values:
            g = float(m.sel(s0=s0, st=st))
            if np.isfinite(g):
                at = {"s0": s0, "st": st}
                out.append({"s0": float(s0), "st": float(st), "baseline": float(base.sel(at)),
                            "gain_pct": g, "ci95": float(h.sel(at)), "pct_min": float(lo.sel(at)),
                            "pct_max": float(hi.sel(at)), "gain_abs": float(ma.sel(at)), "abs_ci95": float(ha.sel(at)),
                            "abs_min": float(alo.sel(at)), "abs_max": float(ahi.sel(at))})
    return out


def series(data: dict) -> dict[tuple[str, str], list[xr.Dataset]]:
    """(method, net) -> fine-tuning datasets (dims s0, st, seed) from every sweep present in
    ``data``; the ceilings as ``ceiling pathwise`` / ``ceiling score_paper`` / ``ceiling gradient``."""
    out: dict = {}

    def add(method, net, ds):
        out.setdefault((str(method), net), []).append(ds)

    for name, net in (("gift_awgn_deep", "deep"), ("gift_regime", "deep"), ("gift_awgn_shallow", "shallow")):
        if name in data:
            add("gift", net, data[name])
    if "variants" in data:
        for v in data["variants"]["variant"].values:
            add(v, "deep", data["variants"].sel(variant=v, drop=True))
    for name, net in (("rivals_regime", "deep"), ("extended", "deep"), ("rivals", "shallow")):
        if name in data:
            for mth in data[name]["method"].values:
                add(mth, net, data[name].sel({"method": mth}, drop=True))
    for name, net in (("ceiling_deep", "deep"), ("ceiling_extended", "deep"), ("ceiling_shallow", "shallow")):
        if name in data:
            for kind in ("pathwise", "score_paper", "gradient"):
                if f"{kind}_accuracy_best" in data[name]:
                    add(f"ceiling {kind}", net, ceiling_as_finetune(data[name], kind))
    return out


def _points(parts: list, split: str) -> list[dict]:
    """The cells of one (method, net) over its sweeps; a cell in two sweeps (gift at one cell of
    both grids) is taken once, from the first (the one with more seeds comes first in series)."""
    seen, pts = set(), []
    for ds in parts:
        for r in cell_points(ds, split):
            if (r["s0"], r["st"]) not in seen:
                seen.add((r["s0"], r["st"]))
                pts.append(r)
    return pts


def draw(data: dict, ax=None, split: str = "train"):
    """Two rows (relative %, absolute points) by one column per method family. ``ax``: a 2 x 4
    array of axes to draw into. Returns the Figure."""
    if ax is None:
        fig, axes = plt.subplots(2, len(FAMILIES), figsize=(5.2 * len(FAMILIES), 11), sharex=True)
    else:
        axes = np.asarray(ax)
        fig = axes.flat[0].figure
    ser = series(data)
    xs = np.linspace(0.08, 1.0, 200)
    for col, (title, methods) in enumerate(FAMILIES):
        for row, (key, lo_key, hi_key, bound) in enumerate((("gain_pct", "pct_min", "pct_max", 100 * (1 / xs - 1)),
                                                            ("gain_abs", "abs_min", "abs_max", 100 * (1 - xs)))):
            a = axes[row][col]
            ys = [0.0, PAPER_PCT]
            any_shallow = False
            for rank, (method, colour, marker) in enumerate(methods):
                for net in ("deep", "shallow"):
                    pts = _points(ser.get((method, net), []), split)
                    if not pts:
                        continue
                    x = np.array([r["baseline"] for r in pts])
                    y = np.array([r[key] for r in pts])
                    lo = np.array([r[lo_key] for r in pts])
                    hi = np.array([r[hi_key] for r in pts])
                    ys += list(lo) + list(hi)
                    strong = rank < 2 and col == 0  # GIFT and its ceiling: larger, drawn on top
                    a.vlines(x, lo, hi, color=colour, lw=0.7, alpha=0.6, zorder=2 + strong)
                    a.plot(x, y, ls="none", marker=marker, ms=(7 if strong else 5) if net == "deep" else 4,
                           color=colour, mfc=colour if net == "deep" else "none", mew=1.0, zorder=3 + strong,
                           label=LABELS.get(method, method) if net == "deep" else None)
                    any_shallow = any_shallow or net == "shallow"
            top, bottom = max(ys) * 1.08 + 2, min(ys) * 1.08 - 2
            a.plot(xs, bound, ":", color="black", lw=0.8, label="largest possible")
            a.axhline(PAPER_PCT, color="crimson", ls="--", lw=1.2, label="28 (% or points)")
            a.axhline(0, color="grey", lw=0.8)
            a.set_ylim(bottom, top)
            a.set_xlim(0.0, 1.0)
            a.grid(alpha=0.25)
            if row == 0:
                a.set_title(title, fontsize=10)
                if any_shallow:  # one entry for the hollow markers instead of a second entry per method
                    a.plot([], [], ls="none", marker="o", mfc="none", color="grey", label="hollow: the shallower net")
                handles, labels = a.get_legend_handles_labels()
            else:  # the column's legend under it, off the data
                a.legend(handles, labels, fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
                         frameon=False)
                a.set_xlabel(f"baseline accuracy of w0 on the chip ({'training' if split == 'train' else 'test'} data)")
    axes[0][0].set_ylabel("relative accuracy gain, %")
    axes[1][0].set_ylabel("absolute accuracy gain, accuracy points")
    fig.suptitle("accuracy gain against w0's baseline accuracy on the chip, one marker per (s0, st) cell and method "
                 f"({'training' if split == 'train' else 'test'} data): the mean over seeds, the bar the seeds' range "
                 "(top: the best single run);\ndeeper net filled, shallower hollow; dashed: 28; dotted: the largest "
                 "gain possible at that baseline", fontsize=10)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
