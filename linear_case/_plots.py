"""Plots from the closed forms: Theorem-1 bound regions in the (s0, st) plane and the
curves of J_s0, J_st around their minimisers (paper fig:example-fine-tuning)."""

from __future__ import annotations


import numpy as np

from gift_theory._io import save_figure

from ._closed import chain_printed_rhs, example_rhs


def _save(fig, path):
    save_figure(fig, path, bbox_inches=None)


def plot_bound_regions(path: str, depths=(1, 2, 3), V_norms=(0.5, 1.0, 2.0), m2: float = 1.0, n: int = 241):
    """Regions of the (s0, st) plane where each condition of Theorem 1 admits st
    (linear example, input noise, balanced chain factorisation):
    printed eq. condition finetuning works linear net, the printed ass:Laplacian-properties
    evaluated exactly at depth L, the corrected bound |st - s0| < 2 s0, and the true region
    (C1 != 0: every st != s0). Returns the path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = np.linspace(1e-3, 2.0, n)
    S0, ST = np.meshgrid(s, s)
    fig, axes = plt.subplots(len(V_norms), len(depths), figsize=(3.2 * len(depths), 3.0 * len(V_norms)),
                             squeeze=False, sharex=True, sharey=True)
    for i, Vn in enumerate(V_norms):
        for j, L in enumerate(depths):
            ax = axes[i, j]
            gap = np.abs(ST - S0)
            true_region = gap > 0
            ax.contourf(S0, ST, true_region.astype(float), levels=[0.5, 1.5], colors=["#e8f4e8"])
            ax.contour(S0, ST, gap - 2 * S0, levels=[0], colors="green")
            ax.contour(S0, ST, gap - example_rhs(S0, m2, Vn), levels=[0], colors="red", linestyles="--")
            ax.contour(S0, ST, gap - chain_printed_rhs(S0, L, Vn, m2), levels=[0], colors="blue", linestyles=":")
            ax.plot(s, s, color="k", lw=0.8)
            ax.set_title(f"L={L}, ||V||={Vn:g}", fontsize=9)
            if i == len(V_norms) - 1:
                ax.set_xlabel("s0")
            if j == 0:
                ax.set_ylabel("st")
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color="red", ls="--", label="printed example bound"),
               Line2D([], [], color="blue", ls=":", label="printed Thm 1 bound at depth L"),
               Line2D([], [], color="green", label="corrected bound |st-s0|<2 s0"),
               Line2D([], [], color="#9c9", lw=6, label="true region (C1 != 0)")]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    _save(fig, path)
    plt.close(fig)
    return path


def plot_example_curves(path: str, V: float = 1.0, m2: float = 1.0, s0: float = 0.3, st: float = 0.6):
    """J_s0 and J_st of the 1-D linear example J_s(W) = m2 (V - W)^2 + s^2 W^2 around their
    minimisers W_s = m2 V / (m2 + s^2) (paper fig:example-fine-tuning, from the closed form)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    W = np.linspace(-0.2 * V, 1.4 * V, 400)
    Js = lambda s: m2 * (V - W) ** 2 + s ** 2 * W ** 2
    w0, wt = m2 * V / (m2 + s0 ** 2), m2 * V / (m2 + st ** 2)
    J = lambda s, w: m2 * (V - w) ** 2 + s ** 2 * w ** 2
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(W, Js(s0), color="red", label=f"J_s0, s0={s0:g}")
    ax.plot(W, Js(st), color="green", label=f"J_st, st={st:g}")
    ax.plot([w0], [J(s0, w0)], "o", color="red")
    ax.plot([w0], [J(st, w0)], "o", mfc="none", color="green", label="J_st(w0)")
    ax.plot([wt], [J(st, wt)], "o", color="green", label="J_st(wt)")
    ax.set_xlabel("W")
    ax.set_ylabel("J")
    ax.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)
    return path
