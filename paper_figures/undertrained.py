"""Ours: the paper's own explanation, tested -- does GIFT gain more from an under-trained w0, and
does that gain come from the noise direction or from a plain gradient step?

Not a paper figure. The paper explains gains at s0 = st by D^[0] being a full-data gradient
against minibatch training; in expectation D^[0] carries no gradient component, so we test it.
On the deeper net, w0 is trained for a few epochs (``train_epochs`` short) and for the default
30; at each (s0, st, seed) we run GIFT (the line search along the pathwise d/ds grad J_s0) and
the same line search along the plain gradient grad J_s0 with the same chip budget, and the
referee's ceiling of both lines (best step chosen on training data, reported on test data),
with the cosine of the two directions (the component of GIFT's direction along the gradient),
and the printed D^[0]'s cosine with the gradient.
Left: relative test accuracy gain per method and training length (mean over cells and seeds,
95 % CI); right: |cos(GIFT direction, gradient)| per point.
Data: sweeps ``undertrained`` (gift_job, dims method, train_epochs, s0, st, seed) and
``undertrained_ceiling`` (ceiling_job with kinds pathwise, score_paper and gradient).
Run: ``python -m paper_figures.undertrained --scale paper``.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ._plot import grid_note, improvements
from .claims import _ci  # one t-interval for the claims and this figure
from .gain_vs_baseline import ceiling_as_finetune

NAME = "undertrained"
LABEL = "ours:undertrained"
SWEEPS = ("undertrained", "undertrained_ceiling")

RULE = ("over the points (s0, st, seed) paired by training length, with 95 % Student-t intervals: "
        "'more' if the ceiling of the GIFT line (test accuracy gain at the step of the best training accuracy) "
        "is larger with the short-trained w0 than with the 30-epoch one (the paired difference's interval lies "
        "above 0), 'not more' if its interval contains 0, 'less' if below 0. Then, with the short-trained w0, "
        "'noise direction' if the GIFT line's ceiling beats the gradient line's (paired interval above 0), else "
        "'gradient step' (a plain gradient step of the same kind gains as much or more). The realised gains of "
        "gift and of the gradient line search with the same chip budget are reported beside them, and the mean "
        "|cos| of the GIFT direction with the gradient")


def _side(m, h) -> int:
    """+1 interval above 0, -1 below, 0 contains 0 (or no interval)."""
    if not (np.isfinite(m) and np.isfinite(h)):
        return 0
    return 1 if m - h > 0 else (-1 if m + h < 0 else 0)


def summarise(under, ceil) -> dict:
    """The numbers, the rule and the verdict of claim ``undertrained_w0`` from the two sweeps."""
    epochs = sorted(int(e) for e in ceil["train_epochs"].values)
    short, long_ = epochs[0], epochs[-1]
    cp = improvements(ceiling_as_finetune(ceil, "pathwise"), "test")["acc_pct"]
    cg = improvements(ceiling_as_finetune(ceil, "gradient"), "test")["acc_pct"]
    real = improvements(under, "train")["acc_pct"]
    rows = {}
    for e in epochs:
        r = {}
        for label, da in (("ceiling_gift_line_test_pct", cp.sel(train_epochs=e)),
                          ("ceiling_gradient_line_test_pct", cg.sel(train_epochs=e)),
                          ("gift_pct", real.sel({"method": "gift", "train_epochs": e})),
                          ("gradient_step_pct", real.sel({"method": "gradient", "train_epochs": e}))):
            m, h, n = _ci(da.values)
            r[label] = {"mean": m, "ci95": h, "n": n}
        base = ceil["test_accuracy_before"].sel(train_epochs=e).values
        r["baseline_test_accuracy"] = float(np.nanmean(base))
        for kind, key in (("pathwise", "abs_cos_gift_gradient"), ("score_paper", "abs_cos_printed_gradient")):
            if f"cos_{kind}_gradient" in ceil:
                m, h, n = _ci(np.abs(ceil[f"cos_{kind}_gradient"].sel(train_epochs=e).values))
                r[key] = {"mean": m, "ci95": h, "n": n}
        rows[str(e)] = r
    d_more = (cp.sel(train_epochs=short) - cp.sel(train_epochs=long_)).values
    d_src = (cp.sel(train_epochs=short) - cg.sel(train_epochs=short)).values
    d_real = (real.sel({"method": "gift", "train_epochs": short})
              - real.sel({"method": "gradient", "train_epochs": short})).values
    more, src, rl = _ci(d_more), _ci(d_src), _ci(d_real)
    s_more, s_src = _side(more[0], more[1]), _side(src[0], src[1])
    if more[2] < 2 or src[2] < 2:
        verdict = "inconclusive"
        text = "too few paired points for an interval"
    elif s_more <= 0:
        verdict = "not supported" if s_more == 0 else "contradicted"
        text = (f"the GIFT line gains {'no more' if s_more == 0 else 'less'} with a w0 of {short} epochs than of "
                f"{long_}")
    elif s_src > 0:
        verdict = "supported"
        text = (f"the GIFT line gains more with a w0 of {short} epochs, and more than the gradient line: the noise "
                f"direction carries it")
    else:
        verdict = "gradient step"
        text = (f"the GIFT line gains more with a w0 of {short} epochs, but the plain gradient line gains as much or "
                f"more: the gain is under-training, not the noise direction")
    cos = rows[str(short)].get("abs_cos_gift_gradient", {}).get("mean", float("nan"))
    return {"epochs": {"short": short, "long": long_}, "per_epochs": rows,
            "ceiling_short_minus_long_pct": {"mean": more[0], "ci95": more[1], "n": more[2]},
            "ceiling_gift_minus_gradient_short_pct": {"mean": src[0], "ci95": src[1], "n": src[2]},
            "realised_gift_minus_gradient_short_pct": {"mean": rl[0], "ci95": rl[1], "n": rl[2]},
            "rule": RULE, "verdict": verdict,
            "summary": (f"{text}: ceiling short - long {more[0]:.2f} ± {more[1]:.2f} %, GIFT line - gradient line "
                        f"(short) {src[0]:.2f} ± {src[1]:.2f} %; realised gift - gradient (short) {rl[0]:.2f} ± "
                        f"{rl[1]:.2f} %; |cos(GIFT, gradient)| {cos:.2f} (short)")}


def draw(data: dict, ax=None):
    """Two panels; ``ax``: two axes to draw into. Returns the Figure."""
    under, ceil = data["undertrained"], data["undertrained_ceiling"]
    if ax is None:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [3, 1]})
    else:
        axes = list(ax)
        fig = axes[0].figure
    s = summarise(under, ceil)
    labels = (("gift_pct", "gift (realised, train)"), ("gradient_step_pct", "gradient line search (realised, train)"),
              ("ceiling_gift_line_test_pct", "ceiling: GIFT line (test)"),
              ("ceiling_gradient_line_test_pct", "ceiling: gradient line (test)"))
    eps = list(s["per_epochs"])
    x = np.arange(len(labels))
    w = 0.8 / len(eps)
    for k, e in enumerate(eps):
        r = s["per_epochs"][e]
        m = [r[key]["mean"] for key, _ in labels]
        h = [r[key]["ci95"] if np.isfinite(r[key]["ci95"]) else 0 for key, _ in labels]
        axes[0].bar(x + (k - (len(eps) - 1) / 2) * w, m, w, yerr=h, capsize=3,
                    label=f"w0 trained {e} epochs (baseline test acc {r['baseline_test_accuracy']:.2f})")
    axes[0].axhline(0, color="grey", lw=0.8)
    axes[0].set_xticks(x, [lab for _, lab in labels], rotation=15, ha="right", fontsize=8)
    axes[0].set_ylabel("relative accuracy gain, %")
    axes[0].legend(fontsize=7)
    axes[0].set_title(f"verdict: {s['verdict']}", fontsize=9)
    if "cos_pathwise_gradient" in ceil:
        for k, e in enumerate(ceil["train_epochs"].values):
            v = np.abs(ceil["cos_pathwise_gradient"].sel(train_epochs=e).values.ravel())
            v = v[np.isfinite(v)]
            axes[1].plot(np.full(v.size, k) + np.linspace(-0.1, 0.1, max(v.size, 1))[:v.size], v, "o", ms=3)
        axes[1].set_xticks(range(ceil.sizes["train_epochs"]), [f"{int(e)} ep" for e in ceil["train_epochs"].values])
        axes[1].set_ylabel("|cos(GIFT direction, gradient)|")
        axes[1].set_ylim(0, 1)
    fig.suptitle(f"does GIFT gain more from an under-trained w0, and from the noise or a gradient step? "
                 f"{grid_note(under)}", fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
