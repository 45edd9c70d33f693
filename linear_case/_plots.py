"""Plots from the closed forms: where each Theorem-1 bound admits st in the (s0, st) plane,
and the curves of J_s0, J_st around their minimisers (paper fig:example-fine-tuning).

Every function draws on the axes it is given (``ax=``) or on a new figure, and returns the
:class:`matplotlib.figure.Figure`; none selects a backend or writes a file, so the plots show
inline in Jupyter and a caller that wants a file calls ``fig.savefig(path)`` (or
``gift_theory.save_figure`` for an atomic write).
"""

from __future__ import annotations

import numpy as np

from ._closed import chain_printed_rhs, example_rhs

#: (key, label, colour, hatch) of the bounds drawn by :func:`plot_bound_regions`
BOUND_STYLES = (
    ("example", "printed example bound (1 + s0²)/(2‖V‖)", "tab:red", "//"),
    ("printed", "printed Thm 1 bound at depth L: 1/‖∇B(w0)‖", "tab:blue", "\\\\"),
    ("corrected", "corrected bound 2 s0", "tab:green", None),
)


def bound_rhs(s0, L: int, V_norm: float, m2: float = 1.0) -> dict:
    """The right-hand sides of the three bounds at s0 (linear example, input noise, balanced
    chain d-1-..-1 of depth L): st is admitted by a bound when 0 < |st - s0| < rhs(s0).

    Parameters
    ----------
    s0 : float or ndarray of any shape
    L : depth; V_norm : ||V||_2; m2 : E[x_i^2]

    Returns
    -------
    dict ``{"example", "printed", "corrected"}`` of arrays shaped like ``s0``.
    """
    s0 = np.asarray(s0, dtype=np.float64)
    return {"example": np.broadcast_to(example_rhs(s0, m2, V_norm), s0.shape),
            "printed": np.asarray(chain_printed_rhs(s0, L, V_norm, m2)),
            "corrected": 2.0 * s0}


def _bound_panel(ax, L, Vn, m2, n, s_max):
    from matplotlib.colors import to_rgba

    s = np.linspace(1e-3, s_max, n)
    S0, ST = np.meshgrid(s, s)
    gap = np.abs(ST - S0)
    rhs = bound_rhs(S0, L, Vn, m2)
    for key, _, colour, hatch in BOUND_STYLES:
        admitted = ((gap > 0) & (gap < rhs[key])).astype(float)
        if hatch is None:   # the corrected bound: a translucent fill
            ax.contourf(S0, ST, admitted, levels=[0.5, 1.5], colors=[to_rgba(colour, 0.22)])
        else:               # the printed bounds: hatching in their colour, no fill
            cs = ax.contourf(S0, ST, admitted, levels=[0.5, 1.5], colors="none", hatches=[hatch])
            cs.set_edgecolor(colour)
            cs.set_linewidth(0)
        ax.contour(S0, ST, gap - rhs[key], levels=[0], colors=[colour], linewidths=1.0)
    ax.plot(s, s, color="k", lw=0.8)
    ax.set_xlim(s[0], s[-1])
    ax.set_ylim(s[0], s[-1])
    ax.set_title(f"L={L}, ‖V‖={Vn:g}", fontsize=9)


def plot_bound_regions(depths=(1, 2, 3), V_norms=(0.5, 1.0, 2.0), m2: float = 1.0, n: int = 241, *,
                       s_max: float = 2.0, ax=None):
    """Where each condition of Theorem 1 admits st (linear example, input noise, balanced chain).

    One panel per (depth L, ||V||): the admitted side of each bound, 0 < |st - s0| < rhs(s0),
    is shaded -- hatched red for the printed example bound (eq. condition finetuning works
    linear net), hatched blue for the printed ass:Laplacian-properties evaluated exactly at
    depth L, filled green for the corrected bound |st - s0| < 2 s0 -- with each boundary as a
    line. The true region is every st != s0 (C1 = 2 s0 (st^2 - s0^2) ||grad B||^2 != 0), so
    only the diagonal (black) is outside it; what lies outside a shaded band is where that
    bound gives no guarantee although fine-tuning helps there.

    Parameters
    ----------
    depths, V_norms : the panels' columns and rows
    m2 : E[x_i^2]; n : grid points per axis; s_max : the plane is (0, s_max]^2
    ax : an Axes (one depth and one ||V||), an array of Axes of shape
        (len(V_norms), len(depths)), or None for a new figure

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    rows, cols = len(V_norms), len(depths)
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows + 0.8), squeeze=False,
                                 sharex=True, sharey=True)
        new = True
    else:
        axes = np.asarray(ax, dtype=object).reshape(rows, cols) if np.ndim(ax) else np.array([[ax]], dtype=object)
        if axes.shape != (rows, cols):
            raise ValueError(f"ax: need {rows} x {cols} axes for V_norms x depths, got {axes.shape}")
        fig = axes[0, 0].figure
        new = False
    for i, Vn in enumerate(V_norms):
        for j, L in enumerate(depths):
            a = axes[i, j]
            _bound_panel(a, L, Vn, m2, n, s_max)
            if i == rows - 1:
                a.set_xlabel("s0")
            if j == 0:
                a.set_ylabel("st")
    handles = [Patch(facecolor="none" if hatch else colour, edgecolor=colour, hatch=hatch,
                     alpha=1 if hatch else 0.35, label=f"admitted by the {label}")
               for _, label, colour, hatch in BOUND_STYLES]
    handles.append(Line2D([], [], color="k", lw=0.8, label="st = s0 (the only st outside the true region)"))
    if new:
        fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8)
        fig.tight_layout(rect=(0, 0.75 / (3.0 * rows + 0.8), 1, 1))
    else:
        axes[0, 0].legend(handles=handles, fontsize=7, loc="upper left")
    return fig


def plot_example_curves(V: float = 1.0, m2: float = 1.0, s0: float = 0.3, st: float = 0.6, *, ax=None):
    """J_s0 and J_st of the 1-D linear example J_s(W) = m2 (V - W)^2 + s^2 W^2 around their
    minimisers W_s = m2 V / (m2 + s^2) (paper fig:example-fine-tuning, from the closed form).

    Returns the Figure (``ax``'s, or a new one).
    """
    if ax is None:
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 3.5))
    else:
        fig = ax.figure
    W = np.linspace(-0.2 * V, 1.4 * V, 400)
    J = lambda s, w: m2 * (V - w) ** 2 + s ** 2 * w ** 2
    w0, wt = m2 * V / (m2 + s0 ** 2), m2 * V / (m2 + st ** 2)
    ax.plot(W, J(s0, W), color="red", label=f"J_s0, s0={s0:g}")
    ax.plot(W, J(st, W), color="green", label=f"J_st, st={st:g}")
    ax.plot([w0], [J(s0, w0)], "o", color="red")
    ax.plot([w0], [J(st, w0)], "o", mfc="none", color="green", label="J_st(w0)")
    ax.plot([wt], [J(st, wt)], "o", color="green", label="J_st(wt)")
    ax.set_xlabel("W")
    ax.set_ylabel("J")
    ax.legend(fontsize=8)
    if ax is fig.axes[0] and len(fig.axes) == 1:
        fig.tight_layout()
    return fig
