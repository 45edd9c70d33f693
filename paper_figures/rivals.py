"""Ours: GIFT and gift-printed beside every rival fine-tuning method, on the same grid.

Not a paper figure. Methods (reference §4): gift, gift-printed (Algorithm 1 exactly as
printed), pathwise, ift, gradient, random, spsa, pat, identify-retrain and retrain (the oracle
that knows st and uses no chip). Top: relative accuracy improvement on training data;
middle: the same on test data; bottom: chip use (in_situ_evaluations, in units of one
Eval_w(K1, K2)). Data: sweep ``rivals`` (dims method, s0, st, seed) on the shallower net.
Run: ``python -m paper_figures.rivals``.
"""

import matplotlib.pyplot as plt
import numpy as np

from ._plot import grid_note, improvements, mean_ci

NAME = "rivals"
LABEL = "ours:rivals"
SWEEPS = ("rivals",)


def draw(data: dict):
    ds = data["rivals"]
    tr, te = improvements(ds, "train"), improvements(ds, "test")
    methods = list(ds["method"].values)
    cells = [(s0, st) for s0 in ds["s0"].values for st in ds["st"].values]
    fig, axes = plt.subplots(3, 1, figsize=(max(8, 0.9 * len(methods) * len(cells) / 2), 9), sharex=True)
    width = 0.8 / len(cells)
    x = np.arange(len(methods))
    evals = ds["in_situ_evaluations"].mean("seed") if "in_situ_evaluations" in ds else None
    for c, (s0, st) in enumerate(cells):
        off = (c - (len(cells) - 1) / 2) * width
        lab = f"$s_0$={s0:g}, $s_t$={st:g}"
        for ax, imp in ((axes[0], tr), (axes[1], te)):
            m, h = mean_ci(imp["acc_pct"].sel(s0=s0, st=st))
            ax.bar(x + off, m.values, width, yerr=h.fillna(0).values, capsize=2, label=lab)
        if evals is not None:
            axes[2].bar(x + off, evals.sel(s0=s0, st=st).values, width, label=lab)
    axes[0].set_ylabel("accuracy improvement, %\n(training data)")
    axes[1].set_ylabel("accuracy improvement, %\n(test data)")
    axes[2].set_ylabel("in-situ evaluations\n(units of Eval(K1, K2))")
    axes[2].set_yscale("symlog", linthresh=1)
    for ax in axes[:2]:
        ax.axhline(0, color="grey", lw=0.8)
    axes[2].set_xticks(x, methods, rotation=30, ha="right")
    axes[0].legend(fontsize=7, ncol=len(cells))
    fig.suptitle(f"GIFT and rivals on the same grid -- {grid_note(ds)}; mean over seeds, 95 % CI", fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
