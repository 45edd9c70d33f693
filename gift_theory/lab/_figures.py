"""Figures of the measurement loop: the error ladder and where-it-fails heatmaps.

Plotting never recomputes the science: each function draws numbers already computed
by :func:`gift_theory.lab.fit_effects`, :func:`gift_theory.lab.diagnose` or
:func:`gift_theory.lab.where_it_fails`.
"""

from __future__ import annotations

import os

import numpy as np

from .._io import save_figure


def _plt():
    import matplotlib

    matplotlib.use("agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path):
    save_figure(fig, path, bbox_inches="tight")


def error_ladder(rungs, noise_floor: float, floor_se: float, path: str, title: str = "error ladder"):
    """Discrepancy (with 2 se bars) of each model version against the floor band.

    Parameters
    ----------
    rungs : sequence of (label, discrepancy, se, p_value)
    noise_floor, floor_se : the measured shots' own floor and its standard error
    path : .png to write
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(rungs), 3.6))
    xs = np.arange(len(rungs))
    d = np.array([r[1] for r in rungs])
    se = np.array([r[2] for r in rungs])
    ax.axhspan(noise_floor - 2 * floor_se, noise_floor + 2 * floor_se, color="0.85", label="noise floor +- 2 se")
    ax.axhline(noise_floor, color="0.5", lw=1)
    colors = ["tab:red" if r[3] < 0.01 else "tab:green" for r in rungs]
    ax.errorbar(xs, d, yerr=2 * se, fmt="none", ecolor="k", capsize=4)
    ax.scatter(xs, d, c=colors, zorder=3, s=40)
    for x, r in zip(xs, rungs):
        ax.annotate(f"p={r[3]:.2g}", (x, r[1]), textcoords="offset points", xytext=(6, 4), fontsize=8)
    ax.set_xticks(xs)
    ax.set_xticklabels([r[0].replace(" + ", "\n+ ") for r in rungs], fontsize=8)
    ax.set_ylabel("held-out discrepancy")
    ax.set_title(title + "  (red: p < 0.01)", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    _save(fig, path)
    return path


def heatmaps(stats: dict, path: str, title: str = "where the model fails"):
    """Per-cell standardised statistics as heatmaps over (layer, neuron) x input bin.

    ``stats`` is the output of :func:`gift_theory.lab.where_it_fails`: for each statistic
    name an array (rows = "layer:neuron", columns = bins of the model's pre-activation).
    """
    plt = _plt()
    names = [k for k in stats["maps"]]
    fig, axes = plt.subplots(1, len(names), figsize=(2.6 * len(names), 0.5 + 0.14 * len(stats["rows"])), squeeze=False)
    for ax, name in zip(axes[0], names):
        M = np.asarray(stats["maps"][name], float)
        lim = max(float(np.nanmax(np.abs(M))) if np.isfinite(M).any() else 1.0, 3.0)
        # every statistic is standardised (N(0, 1) under the model): one symmetric scale
        im = ax.imshow(M, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("pre-activation bin", fontsize=8)
        ax.set_yticks(range(len(stats["rows"])))
        ax.set_yticklabels(stats["rows"] if ax is axes[0][0] else [], fontsize=5)
        fig.colorbar(im, ax=ax, fraction=0.05)
    fig.suptitle(title, fontsize=10)
    _save(fig, path)
    return path


def diagnosis_figures(diagnosis, folder: str) -> list[str]:
    """The figures of a :class:`~gift_theory.lab.Diagnosis`: the error ladder of the baseline and
    the three best candidates, and where the baseline fails."""
    c = diagnosis.baseline_comparison
    rungs = [("awgn", c.discrepancy, c.se, c.p_value)] + [
        ("awgn + " + " + ".join(cand.effects), cand.comparison.discrepancy, cand.comparison.se, cand.comparison.p_value)
        for cand in diagnosis.ranking[:3]]
    out = [error_ladder(rungs, c.noise_floor, c.floor_se, os.path.join(folder, "ladder.png"),
                        title="baseline and best candidates")]
    if diagnosis.where is not None:
        out.append(heatmaps(diagnosis.where, os.path.join(folder, "where.png"), title="baseline: where it fails"))
    return out


def fit_figures(result, folder: str) -> list[str]:
    """The error ladder of a :class:`~gift_theory.lab.FitResult`."""
    rungs = [(lab, c.discrepancy, c.se, c.p_value) for lab, c in result.ladder]
    return [error_ladder(rungs, result.comparison_after.noise_floor, result.comparison_after.floor_se,
                         os.path.join(folder, "ladder.png"))]
