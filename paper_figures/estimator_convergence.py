"""Ours: convergence of the d/ds grad J estimators, error against K1*K2 (log-log).

Not a paper figure; it tests the paper's Section "Calculation of (d/ds) grad J" (eqs.
sample_D0_Wi, sample_D0_bi) against the estimators of ``gift_theory.estimators.d_ds_grad``:
score_paper (D^[0] as printed), score (derived constants, leave-one-out baseline), pathwise
(autodiff at fixed standard draws) and fd (central differences in s, common random numbers).

Error: |D - D_ref| / |D_ref| with D_ref the pathwise estimate on ALL training inputs with
``ref_K2`` draws each; the reference's own variance is subtracted (E|D - D_ref|^2 =
E|D - D*|^2 + E|D_ref - D*|^2 for independent draws). K1 inputs are drawn with replacement;
at fixed K2 the error should fall like (K1 K2)^(-1/2) (the dotted slope). score_paper is
shown rescaled by 1/(-s/2) (solid) and as printed (dashed, against d/ds grad J itself: it
cannot converge, since E[D^[0]] = -(s/2) d/ds grad J). Data: sweep ``estimators``.
Run: ``python -m paper_figures.estimator_convergence``.
"""

import json

import matplotlib.pyplot as plt
import numpy as np

NAME = "estimator_convergence"
LABEL = "ours:estimator_convergence"
SWEEPS = ("estimators",)


def slope(ds, method, K2, var="rel_error_debiased"):
    """Least-squares slope of log error against log K1*K2 at fixed K2 (mean over reps)."""
    e = ds[var].sel({"method": method, "K2": K2}).mean("rep")
    n = ds["K1"].values * K2
    ok = np.isfinite(e.values) & (e.values > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(n[ok]), np.log(e.values[ok]), 1)[0])


def draw(data: dict):
    ds = data["estimators"]
    fixed = json.loads(ds.attrs.get("fixed_json", "{}"))
    fig, ax = plt.subplots(figsize=(7, 5))
    colors = dict(zip(ds["method"].values, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    markers = ["o", "s", "^", "D"]
    n_all = []
    for method in ds["method"].values:
        for k, K2 in enumerate(ds["K2"].values):
            n = ds["K1"].values * K2
            n_all += list(n)
            e = ds["rel_error_debiased"].sel({"method": method, "K2": K2})
            ax.loglog(n, e.mean("rep").values, marker=markers[k % 4], color=colors[method], alpha=0.8,
                      ls="-" if method != "fd" else (0, (4, 2)),
                      label=f"{method}, K2={K2} (slope {slope(ds, method, K2):.2f})")
            if method == "score_paper":
                ax.loglog(n, ds["rel_error"].sel({"method": method, "K2": K2}).mean("rep").values, ls="--",
                          marker=markers[k % 4], color=colors[method], alpha=0.6)
    n_all = np.array(sorted(set(n_all)), float)
    # the slope guide starts at the pathwise estimator's smallest budget (the one expected to be best)
    m0 = "pathwise" if "pathwise" in ds["method"].values else ds["method"].values[0]
    first = ds["rel_error_debiased"].sel({"method": m0}).isel(K1=0, K2=0).mean("rep")
    ref_err = float(first) if np.isfinite(float(first)) else 1.0
    ax.loglog(n_all, ref_err * (n_all / n_all[0]) ** -0.5, "k:", label="slope -1/2")
    floor = float(ds["ref_rel_se"].mean())
    ax.axhline(floor, color="grey", lw=0.8, ls="-.", label=f"reference's own rel. s.e. {floor:.2f}")
    ax.set_xlabel("K1 x K2 (inputs x noise draws)")
    ax.set_ylabel(r"relative error $|D - D_{ref}| / |D_{ref}|$ (debiased)")
    ax.set_title(f"d/ds grad J estimators: net {fixed.get('arch')}, s = {fixed.get('s0')}, data "
                 f"{fixed.get('dataset')}, {ds.sizes['rep']} reps\n(faint dashed: score_paper as printed, unscaled; fd lies on pathwise)",
                 fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
