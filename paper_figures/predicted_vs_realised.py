"""Ours: Theorem 1's first-order prediction of the change of J_st against the realised change.

Not a paper figure; it is the "confirm the predicted improvements" figure. Theorem 1 (paper,
thm:main) rests on dJ_st(a) = J_st(w0 + a u) - J_st(w0) ~ a <grad J_st(w0), u> along the unit
GIFT direction u. For every GIFT point of the sweeps ``gift_awgn_deep``, ``gift_awgn_shallow``
and ``gift_violated``, x is that prediction at the line search's best measured step a, with
<grad J_st(w0), u> estimated in silico (AWGN at the chip's noise standard deviation), and y
is the referee's realised change at the same step (true physics, paired, 32 draws per
input); error bars are one standard error each way. Left: first order (Theorem 1); right:
with the in-silico curvature at s0 added (a^2 u^T H u / 2). The line is y = x. Hollow
markers: the confirmation did not accept the step (the run returned w0).

:func:`summarise` gives the correlation (Pearson, 95 % Fisher-z interval), the regression slope
of realised on predicted, and the points where the prediction is wrong: |realised - predicted|
above 3 combined standard errors, or a predicted decrease (beyond 2 se) that realised as an
increase (beyond 2 se). Run: ``python -m paper_figures.predicted_vs_realised``.
"""

from __future__ import annotations

import numpy as np

NAME = "predicted_vs_realised"
LABEL = "ours:predicted_vs_realised"
SWEEPS = ("gift_awgn_deep", "gift_awgn_shallow", "gift_violated")
KEYS = ("predicted_change", "predicted_change_se", "predicted_change_2nd", "realised_change", "realised_change_se")
Z_WRONG = 3.0
Z_SIGN = 2.0


def points(data: dict) -> list[dict]:
    """One record per finished GIFT point with a prediction: group, grid coordinates and the numbers."""
    out = []
    for sweep in SWEEPS:
        ds = data.get(sweep)
        if ds is None:
            continue
        missing = [k for k in KEYS if k not in ds]
        if missing:
            raise RuntimeError(f"needs {', '.join(missing)} in sweep {sweep} (rerun it with the current gift_job)")
        flat = ds.stack(point=list(ds[KEYS[0]].dims))
        for i in range(flat.sizes["point"]):
            p = flat.isel(point=i)
            if not (bool(p["done"]) and np.isfinite(float(p["predicted_change"]))
                    and np.isfinite(float(p["realised_change"]))):
                continue
            coords = {d: (str(p[d].values) if p[d].dtype.kind in "US" else float(p[d].values))
                      for d in ds[KEYS[0]].dims}
            group = (sweep.replace("gift_awgn_", "awgn, ") + " net") if sweep != "gift_violated" else \
                f"{coords['noise_kind']}, deep net"
            rec = {"sweep": sweep, "group": group, **coords, **{k: float(p[k]) for k in KEYS}}
            rec["accepted"] = bool(float(p["accepted"])) if "accepted" in p and np.isfinite(float(p["accepted"])) \
                else None
            out.append(rec)
    return out


def _pearson(x, y):
    n = len(x)
    if n < 4 or np.std(x) == 0 or np.std(y) == 0:
        return float("nan"), (float("nan"), float("nan"))
    r = float(np.corrcoef(x, y)[0, 1])
    z, h = np.arctanh(np.clip(r, -0.999999, 0.999999)), 1.959964 / np.sqrt(n - 3)
    return r, (float(np.tanh(z - h)), float(np.tanh(z + h)))


def summarise(data: dict) -> dict:
    """Correlation, regression slope and the wrong predictions (rules in the module docstring)."""
    pts = points(data)
    if not pts:
        raise RuntimeError("no GIFT point with a prediction in the sweeps")
    pred = np.array([p["predicted_change"] for p in pts])
    pred2 = np.array([p["predicted_change_2nd"] for p in pts])
    real = np.array([p["realised_change"] for p in pts])
    se = np.sqrt(np.array([p["predicted_change_se"] for p in pts]) ** 2
                 + np.array([p["realised_change_se"] for p in pts]) ** 2)
    r, ci = _pearson(pred, real)
    ok2 = np.isfinite(pred2)
    r2, ci2 = _pearson(pred2[ok2], real[ok2])
    slope = float(np.polyfit(pred, real, 1)[0]) if len(pts) > 2 and np.std(pred) > 0 else float("nan")
    z = (real - pred) / np.where(se > 0, se, np.inf)
    real_se = np.array([p["realised_change_se"] for p in pts])
    pred_se = np.array([p["predicted_change_se"] for p in pts])
    sign = (pred < -Z_SIGN * pred_se) & (real > Z_SIGN * real_se)
    wrong = [dict(pts[i], z=float(z[i]), sign_wrong=bool(sign[i]))
             for i in np.flatnonzero((np.abs(z) > Z_WRONG) | sign)]
    ratio = real / np.where(pred != 0, pred, np.nan)
    return {"points": len(pts), "correlation": r, "correlation_ci95": ci, "correlation_2nd_order": r2,
            "correlation_2nd_order_ci95": ci2, "slope_realised_on_predicted": slope,
            "median_realised_over_predicted": float(np.nanmedian(ratio)),
            "wrong": len(wrong), "sign_wrong": int(sign.sum()), "wrong_points": wrong,
            "rule": f"a prediction is wrong when |realised - predicted| > {Z_WRONG:g} combined standard errors, "
                    f"or it predicts a decrease of J_st beyond {Z_SIGN:g} se that realises as an increase beyond "
                    f"{Z_SIGN:g} se; correlation: Pearson over all points, 95 % Fisher-z interval"}


def draw(data: dict):
    import matplotlib.pyplot as plt

    from ._plot import grid_note

    pts = points(data)
    s = summarise(data)
    groups = sorted({p["group"] for p in pts})
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.5))
    for ax, key, title, (r, ci) in (
            (axes[0], "predicted_change", "first order (Theorem 1)", (s["correlation"], s["correlation_ci95"])),
            (axes[1], "predicted_change_2nd", "first order + in-silico curvature",
             (s["correlation_2nd_order"], s["correlation_2nd_order_ci95"]))):
        for c, g in enumerate(groups):
            sub = [p for p in pts if p["group"] == g and np.isfinite(p[key])]
            if not sub:
                continue
            x = np.array([p[key] for p in sub])
            y = np.array([p["realised_change"] for p in sub])
            xe = np.array([p["predicted_change_se"] for p in sub])
            ye = np.array([p["realised_change_se"] for p in sub])
            ax.errorbar(x, y, xerr=xe, yerr=ye, fmt="none", ecolor=f"C{c}", alpha=0.5, lw=0.8)
            acc = np.array([bool(p["accepted"]) for p in sub])
            ax.scatter(x[acc], y[acc], color=f"C{c}", s=18, label=g)
            ax.scatter(x[~acc], y[~acc], facecolors="none", edgecolors=f"C{c}", s=18)
        vals = np.array([p[key] for p in pts if np.isfinite(p[key])] + [p["realised_change"] for p in pts])
        lim = float(np.max(np.abs(vals))) * 1.1 if vals.size else 1.0
        ax.plot([-lim, lim], [-lim, lim], "k--", lw=0.8, label="y = x")
        ax.axhline(0, color="grey", lw=0.5)
        ax.axvline(0, color="grey", lw=0.5)
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
        ax.set_xlabel(r"predicted $\Delta J_{s_t}$ at the chosen step (in silico)")
        ax.set_ylabel(r"realised $\Delta J_{s_t}$ (referee)")
        ax.set_title(f"{title}: r = {r:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]", fontsize=9)
    axes[0].legend(fontsize=7, loc="upper left")
    notes = "\n".join(f"{k.replace('gift_', '')}: {grid_note(data[k])}" for k in SWEEPS if k in data)
    fig.suptitle(f"Theorem 1's first-order change of J_st along the GIFT direction vs the referee: {s['points']} "
                 f"points, {s['wrong']} wrong by the rule ({s['sign_wrong']} of the wrong sign), realised/predicted "
                 f"median {s['median_realised_over_predicted']:.2f}; hollow: not accepted\n{notes}", fontsize=8)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
