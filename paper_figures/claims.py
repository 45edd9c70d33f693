"""The paper's simulation-study claims, each set against our saved sweep data.

Claims (paper Sections "Simulation study on GIFT" and abstract):

* ``accuracy_gain_up_to_28pct`` -- "GIFT achieves up to 28% relative accuracy improvement".
* ``deeper_benefits_more`` -- the shallower net's improvements are "generally lower".
* ``robust_to_non_awgn`` -- meaningful gains under Laplace / multiplicative / uniform true noise.
* ``test_resembles_train`` -- test-data gains "closely resemble" training-data gains.
* ``gains_at_s0_eq_st`` -- "even when s0 = st ... substantial loss improvements".

Every number is computed from the saved netCDF files; the verdicts are rules on those numbers
with 95 % Student-t intervals over seeds (or over grid points), stated in ``rule``. At a scale
other than the paper's (other data, other nets) a verdict says what OUR numbers show, not
whether the paper's own numbers were right.
"""

from __future__ import annotations

import os

import numpy as np
from scipy import stats

from ._plot import improvements, mean_ci
from ._sweep import open_dataset


def _ci(values) -> tuple[float, float, int]:
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    n = v.size
    if n == 0:
        return float("nan"), float("nan"), 0
    if n == 1:
        return float(v[0]), float("nan"), 1
    return float(v.mean()), float(stats.t.ppf(0.975, n - 1) * v.std(ddof=1) / np.sqrt(n)), n


def _fmt(m, h) -> str:
    return f"{m:.2f}" + (f" ± {h:.2f}" if np.isfinite(h) else "")


def _load(data_dir, name, loaded=None):
    if loaded is not None and name in loaded:
        return loaded[name]
    path = os.path.join(data_dir, f"{name}.nc")
    return open_dataset(path) if os.path.isfile(path) else None


def summarise(data_dir: str, loaded: dict | None = None) -> dict:
    """Claims -> {numbers..., verdict, rule, summary} from the sweeps saved in ``data_dir``
    (``loaded``: sweeps already read, by name)."""
    out = {}
    deep, shallow, viol = (_load(data_dir, n, loaded) for n in ("gift_awgn_deep", "gift_awgn_shallow", "gift_violated"))
    if deep is None:
        raise FileNotFoundError(f"no gift_awgn_deep.nc in {data_dir}: run the GIFT sweeps first")
    imp_d = improvements(deep, "train")

    # 1. up to 28 % relative accuracy gain
    mean, half = mean_ci(imp_d["acc_pct"])
    flat = mean.stack(cell=("s0", "st"))
    i = int(np.nanargmax(flat.values))
    best = flat.isel(cell=i)
    hbest = half.stack(cell=("s0", "st")).isel(cell=i)
    pmax = float(imp_d["acc_pct"].max())
    out["accuracy_gain_up_to_28pct"] = {
        "best_cell_mean_pct": float(best), "best_cell_ci95": float(hbest), "best_cell": {
            "s0": float(best["s0"]), "st": float(best["st"])}, "best_single_run_pct": pmax,
        "rule": "reproduced if the best cell's mean relative accuracy gain is >= 28 %; 'gains, smaller' if its "
                "95 % CI lies above 0 but the mean is below 28 %; else 'not reproduced'",
        "verdict": "reproduced" if float(best) >= 28 else (
            "gains, smaller" if np.isfinite(float(hbest)) and float(best) - float(hbest) > 0 else "not reproduced"),
        "summary": f"best mean gain {_fmt(float(best), float(hbest))} % at s0={float(best['s0']):g}, "
                   f"st={float(best['st']):g} (best single run {pmax:.2f} %); paper: up to 28 %"}

    # 2. deeper benefits more (same grid, paired by s0, st, seed)
    if shallow is not None:
        imp_s = improvements(shallow, "train")
        rows = {}
        for var in ("acc_pct", "loss_pct"):
            d = (imp_d[var] - imp_s[var]).values
            m, h, n = _ci(d)
            rows[var] = {"deep_mean": float(imp_d[var].mean()), "shallow_mean": float(imp_s[var].mean()),
                         "paired_diff_mean": m, "paired_diff_ci95": h, "n": n}
        m, h = rows["acc_pct"]["paired_diff_mean"], rows["acc_pct"]["paired_diff_ci95"]
        ml, hl = rows["loss_pct"]["paired_diff_mean"], rows["loss_pct"]["paired_diff_ci95"]
        verdict = ("supported" if m - h > 0 and ml - hl > 0 else
                   "contradicted" if m + h < 0 and ml + hl < 0 else "inconclusive")
        out["deeper_benefits_more"] = {
            **rows, "rule": "supported if deep - shallow (paired over s0, st, seed) has a 95 % CI above 0 for "
                            "both relative accuracy and loss gains; contradicted if below 0 for both",
            "verdict": verdict,
            "summary": f"deep - shallow: accuracy gain {_fmt(m, h)} pp of %, loss gain {_fmt(ml, hl)} pp of % "
                       f"(deep {rows['acc_pct']['deep_mean']:.2f} % vs shallow {rows['acc_pct']['shallow_mean']:.2f} "
                       f"% accuracy)"}

    # 3. robustness to non-AWGN true noise
    if viol is not None:
        imp_v = improvements(viol, "train")
        per = {}
        parts = []
        for kind in viol["noise_kind"].values:
            sub = imp_v.sel(noise_kind=kind)
            acc_m = sub["acc_pct"].mean("seed")
            loss_m = sub["loss_pct"].mean("seed")
            a, ha, _ = _ci(sub["acc_pct"].values)
            lo, hl, _ = _ci(sub["loss_pct"].values)
            per[str(kind)] = {"acc_pct_mean": a, "acc_pct_ci95": ha, "loss_pct_mean": lo, "loss_pct_ci95": hl,
                              "acc_cells_improved": int((acc_m > 0).sum()), "cells": int(acc_m.size),
                              "acc_pct_worst_cell": float(acc_m.min()), "acc_pct_best_cell": float(acc_m.max()),
                              "loss_pct_worst_cell": float(loss_m.min())}
            parts.append(f"{kind}: accuracy {_fmt(a, ha)} %, loss {_fmt(lo, hl)} %, "
                         f"{per[str(kind)]['acc_cells_improved']}/{per[str(kind)]['cells']} cells improve accuracy")
        ok = all(v["loss_pct_worst_cell"] >= 0 and v["acc_pct_mean"] - (v["acc_pct_ci95"] if np.isfinite(
            v["acc_pct_ci95"]) else 0) > 0 for v in per.values())
        bad = any(v["acc_pct_mean"] + (v["acc_pct_ci95"] if np.isfinite(v["acc_pct_ci95"]) else 0) < 0
                  for v in per.values())
        out["robust_to_non_awgn"] = {
            "per_noise_kind": per,
            "rule": "supported if for every law no cell's mean loss gets worse and the mean accuracy gain over "
                    "all points has a 95 % CI above 0; contradicted if some law's CI is below 0",
            "verdict": "supported" if ok else ("contradicted" if bad else "inconclusive"),
            "summary": "; ".join(parts)}

    # 4. test-data gains resemble training-data gains
    imp_t = improvements(deep, "test")
    rows = {}
    for var in ("acc_pct", "loss_pct"):
        tr, te = imp_d[var].mean("seed").values.ravel(), imp_t[var].mean("seed").values.ravel()
        ok = np.isfinite(tr) & np.isfinite(te)
        r = float(np.corrcoef(tr[ok], te[ok])[0, 1]) if ok.sum() > 2 and np.std(tr[ok]) > 0 and np.std(
            te[ok]) > 0 else float("nan")
        m, h, n = _ci((imp_t[var] - imp_d[var]).values)
        rows[var] = {"train_mean": float(np.nanmean(tr)), "test_mean": float(np.nanmean(te)),
                     "cell_correlation": r, "test_minus_train_mean": m, "test_minus_train_ci95": h}
    close = {var: abs(v["test_mean"] - v["train_mean"]) <= 0.25 * max(abs(v["train_mean"]), abs(v["test_mean"]))
             + (v["test_minus_train_ci95"] if np.isfinite(v["test_minus_train_ci95"]) else 0.0)
             for var, v in rows.items()}
    out["test_resembles_train"] = {
        **rows, "close": close,
        "rule": "supported if, for accuracy and loss, |test - train| mean gain <= 25 % of the larger of the two plus "
                "the 95 % CI of the paired difference, and the cell-wise correlation of loss gains is > 0.5",
        "verdict": "supported" if all(close.values()) and rows["loss_pct"]["cell_correlation"] > 0.5
        else "not supported",
        "summary": f"accuracy gain train {rows['acc_pct']['train_mean']:.2f} % vs test "
                   f"{rows['acc_pct']['test_mean']:.2f} % (cell corr {rows['acc_pct']['cell_correlation']:.2f}); "
                   f"loss gain train {rows['loss_pct']['train_mean']:.2f} % vs test "
                   f"{rows['loss_pct']['test_mean']:.2f} % (corr {rows['loss_pct']['cell_correlation']:.2f})"}

    # 5. gains at s0 = st
    diag = [(s, s) for s in deep["s0"].values if s in deep["st"].values]
    if diag:
        vals = {var: np.concatenate([imp_d[var].sel(s0=a, st=b).values.ravel() for a, b in diag])
                for var in ("loss_pct", "acc_pct")}
        lm, lh, n = _ci(vals["loss_pct"])
        am, ah, _ = _ci(vals["acc_pct"])
        out["gains_at_s0_eq_st"] = {
            "loss_pct_mean": lm, "loss_pct_ci95": lh, "acc_pct_mean": am, "acc_pct_ci95": ah, "n": n,
            "cells": [float(a) for a, _ in diag],
            "rule": "supported if the mean relative loss gain over the s0 = st points has a 95 % CI above 0",
            "verdict": "supported" if np.isfinite(lh) and lm - lh > 0 else (
                "inconclusive" if not np.isfinite(lh) or lm + lh > 0 else "contradicted"),
            "summary": f"on s0 = st ({n} runs): loss gain {_fmt(lm, lh)} %, accuracy gain {_fmt(am, ah)} %"}
    return out


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(summarise(sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "data", "quick")), indent=2, default=float))
