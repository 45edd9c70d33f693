"""fig:performance_gift_violated_noise_assumption -- GIFT when the true noise is not AWGN.

Paper caption: "Percentage improvements in loss (top) and accuracy (bottom) achieved by
Algorithm 1 compared to the baseline (no fine-tuning) for the deeper network under violations
of the AWGN assumption. Results are shown for Laplace-distributed noise (left), multiplicative
Gaussian noise (middle), and uniformly distributed noise (right). Confidence intervals
represent 95%."

The paper's laws U(-st, st), Laplace(0, st) and multiplicative Gaussian with std st are mapped
onto reference §2 exactly (:func:`paper_figures._jobs.true_noise`): uniform with s = st/sqrt(3),
laplace with s = st*sqrt(2), multiplicative m = st with the additive awgn switched OFF. GIFT
itself still assumes AWGN at s0. Data: sweep ``gift_violated`` (dims noise_kind, s0, st, seed).
Run: ``python -m paper_figures.performance_gift_violated_noise_assumption``.
"""

import matplotlib.pyplot as plt

from ._plot import grid_note, improvements, mean_ci

NAME = "performance_gift_violated_noise_assumption"
LABEL = "fig:performance_gift_violated_noise_assumption"
SWEEPS = ("gift_violated",)

KIND_TITLES = {
    "laplace": "Laplace(0, $s_t$): laplace, s = $s_t\\sqrt{2}$",
    "multiplicative": "multiplicative, std $s_t$: m = $s_t$, awgn off",
    "uniform": "U($-s_t$, $s_t$): uniform, s = $s_t/\\sqrt{3}$",
}


def lines_with_ci(ax, da, ylabel):
    """Mean over seeds against st, one line per s0, 95 % CI error bars."""
    mean, half = mean_ci(da)
    for s0 in mean["s0"].values:
        m = mean.sel(s0=s0)
        h = half.sel(s0=s0)
        ax.errorbar(m["st"].values, m.values, yerr=h.fillna(0).values, marker="o", ms=4, capsize=3,
                    label=f"$s_0$={s0:g}")
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xlabel(r"true noise parameter $s_t$")
    ax.set_ylabel(ylabel)


def draw_split(ds, split: str, kinds, title: str):
    imp = improvements(ds, split)
    fig, axes = plt.subplots(2, len(kinds), figsize=(4.2 * len(kinds), 6.5), squeeze=False)
    for j, kind in enumerate(kinds):
        sub = imp.sel(noise_kind=kind)
        lines_with_ci(axes[0, j], sub["loss_pct"], "loss improvement, %")
        lines_with_ci(axes[1, j], sub["acc_pct"], "accuracy improvement, %")
        axes[0, j].set_title(KIND_TITLES[kind], fontsize=9)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{title}\n{grid_note(ds)}; mean over seeds, 95 % CI (Student t over seeds)", fontsize=9)
    fig.tight_layout()
    return fig


def draw(data: dict):
    return draw_split(data["gift_violated"], "train", ("laplace", "multiplicative", "uniform"),
                      "fig:performance_gift_violated_noise_assumption -- deeper net, training data, "
                      "GIFT assumes AWGN")


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
