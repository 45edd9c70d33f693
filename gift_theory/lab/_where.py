"""Where the model fails, and the signature of each effect in the residuals.

:func:`where_it_fails` computes per-cell standardised statistics (one cell = one input x
one neuron of one measured layer; each is N(0, 1) under the model up to the normal
approximation): mean residual z, log variance ratio, excess kurtosis difference, PIT,
cross-neuron correlation and trend with acquisition time, and bins them over the
model's noiseless pre-activation (heatmap rows = layer:neuron, columns = bins; a bin
holds ``sum z / sqrt(count)``, again N(0, 1) under the model).

:func:`signatures` turns the residuals into one standardised score per effect of
CONTRACTS §2 (a score test in the direction the effect would move the moments; z > 3
stands out). Without taps only the output layer is seen: hidden-layer effects are
diluted by the layers after them, so every score has less power (it is still valid).
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import stats

from ._compare import Model, model_shots
from ._fit import lattice_step
from ._measurement import Measurement


def _noiseless_pre(model: Model, meas: Measurement):
    """The model's noiseless pre-activations z_l (n, d_l) of every layer."""
    params = model.params if model.params is not None else meas.params
    sigma = meas.arch.sigma
    a = meas.x
    pres = []
    for l, (W, b) in enumerate(params, start=1):
        z = a @ np.asarray(W).T + np.asarray(b)
        pres.append(z)
        a = np.asarray(sigma(z))
    return pres


def _cells(key, model, meas, shots=None):
    Ms = [np.asarray(M, np.float64) for M in model_shots(key, model, meas, shots)]
    return Ms, list(meas.layers())


def _kurt(A):
    c = A - A.mean(1, keepdims=True)
    v = np.mean(c ** 2, 1)
    return np.mean(c ** 4, 1) / np.maximum(v ** 2, 1e-300) - 3.0


def _offdiag_corr(A):
    """Mean off-diagonal correlation per input: (n,)."""
    c = A - A.mean(1, keepdims=True)
    sd = np.sqrt(np.maximum(np.mean(c ** 2, 1), 1e-300))
    z = c / sd[:, None, :]
    C = np.einsum("nkd,nke->nde", z, z) / A.shape[1]
    d = A.shape[2]
    return (C.sum((1, 2)) - np.trace(C, axis1=1, axis2=2)) / max(d * (d - 1), 1)


def where_it_fails(key, model: Model, meas: Measurement, bins: int = 6, shots: int | None = None) -> dict:
    """Per-cell standardised statistics, their heatmaps and the worst cells.

    Returns
    -------
    dict with ``rows`` (list of "layer:neuron"), ``maps`` ({statistic: (rows, bins) array}),
    ``worst`` (list of {layer, neuron, input, statistic, z}, worst first)
    """
    Ms, Ys = _cells(key, model, meas, shots)
    pres = _noiseless_pre(model, meas)
    r = meas.r
    names = ["mean_z", "log_var_ratio", "excess_kurtosis", "pit", "correlation"] + (["time_trend"] if meas.t is not None else [])
    rows, maps, worst = [], {k: [] for k in names}, []
    for l, M, Y in zip(meas.layer_ids(), Ms, Ys):
        K = M.shape[1]
        md, mm = Y.mean(1), M.mean(1)
        vd, vm = Y.var(1, ddof=1), M.var(1, ddof=1)
        floor = 1e-12 * max(vd.mean(), 1e-300)
        cell = {"mean_z": (md - mm) / np.sqrt(vd / r + vm / K + floor),
                "log_var_ratio": (np.log(vd + floor) - np.log(vm + floor)) / np.sqrt(2 / (r - 1) + 2 / (K - 1)),
                "excess_kurtosis": (_kurt(Y) - _kurt(M)) / np.sqrt(24 / r + 24 / K)}
        below = (M[:, None, :, :] < Y[:, :, None, :]).mean(2) + 0.5 * (M[:, None, :, :] == Y[:, :, None, :]).mean(2)
        cell["pit"] = (below.mean(1) - 0.5) / np.sqrt(1 / (12 * r) + 1 / (12 * K))
        dc = _offdiag_corr(Y) - _offdiag_corr(M)
        sd = dc.std(ddof=1) if len(dc) > 1 else 1.0
        cell["correlation"] = np.repeat((dc / max(sd, 1e-300))[:, None], Y.shape[2], 1)
        if meas.t is not None:
            res = (Y - mm[:, None, :]) / np.sqrt(vm[:, None, :] + floor)
            tc = meas.t - meas.t.mean()
            # per cell: residuals against centred time, N(0, 1) under the model
            cell["time_trend"] = np.einsum("nr,nrd->nd", tc, res) / np.sqrt(np.sum(tc ** 2, 1) + 1e-300)[:, None]
        pre = pres[l - 1]
        for j in range(Y.shape[2]):
            rows.append(f"{l}:{j}")
            edges = np.quantile(pre[:, j], np.linspace(0, 1, bins + 1))
            idx = np.clip(np.searchsorted(edges, pre[:, j], side="right") - 1, 0, bins - 1)
            for name in names:
                v = cell[name][:, j]
                row = np.full(bins, np.nan)
                for b_ in range(bins):
                    sel = idx == b_
                    if sel.any():
                        row[b_] = v[sel].sum() / np.sqrt(sel.sum())
                maps[name].append(row)
        # kurtosis of a few dozen shots is far from normal in its tails: shown, not ranked
        for name in ("mean_z", "log_var_ratio", "pit"):
            v = cell[name]
            flat = np.argsort(-np.abs(v), axis=None)[:10]
            for f in flat:
                i, j = np.unravel_index(f, v.shape)
                worst.append({"layer": int(l), "neuron": int(j), "input": int(i), "statistic": name, "z": float(v[i, j])})
    worst.sort(key=lambda w: -abs(w["z"]))
    return {"rows": rows, "maps": {k: np.array(v) for k, v in maps.items()}, "worst": worst}


def _score(e, w):
    """Score-test z of standardised residuals ``e`` in direction ``w`` (N(0,1) under the model)."""
    e, w = np.ravel(e), np.ravel(w)
    ok = np.isfinite(e) & np.isfinite(w)
    e, w = e[ok], w[ok]
    nw = np.sqrt(np.sum(w ** 2))
    return float(np.sum(e * w) / nw) if nw > 0 else float("nan")


def signatures(key, model: Model, meas: Measurement, shots: int | None = None) -> dict:
    """The signature statistic of every CONTRACTS §2 effect in the residuals of ``model``.

    Returns
    -------
    {effect: {"statistic": str, "value": float, "z": float, "stands_out": bool}}
    """
    Ms, Ys = _cells(key, model, meas, shots)
    r = meas.r
    out = {}
    zmean, zvar, wvar_shot, wvar_mult, zkurt, od, wsat, wdrift = [], [], [], [], [], [], [], []
    halves = []
    logex, logmu = [], []
    for M, Y in zip(Ms, Ys):
        K = M.shape[1]
        md, mm = Y.mean(1), M.mean(1)
        vd, vm = Y.var(1, ddof=1), M.var(1, ddof=1)
        fl = 1e-12 * max(vd.mean(), 1e-300)
        se_m = np.sqrt(vd / r + vm / K + fl)
        zmean.append((md - mm) / se_m)
        se_v = np.sqrt(2 * vd ** 2 / (r - 1) + 2 * vm ** 2 / (K - 1) + fl ** 2)
        ex = vd - vm
        zvar.append(ex / se_v)
        wvar_shot.append(np.abs(mm) / se_v)            # shot: excess variance q |v|
        wvar_mult.append(mm ** 2 / se_v)               # multiplicative: m^2 u^2
        wsat.append(-(mm ** 3) / se_m)                 # saturation: v - v^3 / (3 v_max^2)
        if meas.t is not None:
            wdrift.append((meas.t.mean(1) - meas.t.mean())[:, None] * mm / se_m)  # drift: gain 1 + r t
        zkurt.append((_kurt(Y) - _kurt(M)) / np.sqrt(24 / r + 24 / K))
        # common mode adds c^2 u_j u_k to every covariance: score along the rank-one u u^T
        w = mm / np.sqrt(np.mean(mm ** 2) + fl)
        qd = np.var(np.einsum("nrd,nd->nr", Y, w), axis=1, ddof=1) - np.sum(w ** 2 * vd, 1)
        qm = np.var(np.einsum("nrd,nd->nr", M, w), axis=1, ddof=1) - np.sum(w ** 2 * vm, 1)
        od.append(qd - qm)
        h, hk = r // 2, K // 2
        ra = (Y[:, :h].mean(1) - M[:, :hk].mean(1)) / se_m
        rb = (Y[:, h:2 * h].mean(1) - M[:, hk:2 * hk].mean(1)) / se_m
        halves.append((ra, rb))
        big = ex > 3 * se_v
        logex.append(np.log(ex[big]))
        logmu.append(np.log(np.abs(mm[big]) + fl))
    cat = lambda xs: np.concatenate([np.ravel(x) for x in xs]) if xs else np.zeros(0)
    z_shot = _score(cat(zvar), cat(wvar_shot))
    z_mult = _score(cat(zvar), cat(wvar_mult))
    lx, lm = cat(logex), cat(logmu)
    slope = float(np.polyfit(lm, lx, 1)[0]) if len(lx) >= 5 and np.ptp(lm) > 0 else float("nan")
    out["shot"] = {"statistic": f"excess variance along |mean| (shot: variance q|v|); log excess variance vs log|mean| "
                                f"slope {slope:.2f} (~1 shot, ~2 multiplicative) over {len(lx)} cells",
                   "value": slope, "z": z_shot}
    out["multiplicative"] = {"statistic": "excess variance along mean^2 (multiplicative: variance m^2 u^2)",
                             "value": slope, "z": z_mult}
    odv = cat(od)
    z_cm = float(odv.mean() / (odv.std(ddof=1) / np.sqrt(len(odv)))) if len(odv) > 1 and odv.std() > 0 else float("nan")
    out["common_mode"] = {"statistic": "excess off-diagonal covariance along the rank-one direction mean mean^T "
                                       "(the top eigenvector common mode adds)", "value": float(odv.mean()), "z": z_cm}
    zk = cat(zkurt)
    zk_all = float(zk.sum() / np.sqrt(len(zk))) if len(zk) else float("nan")
    ad = _anderson(Ys, Ms)
    out["laplace"] = {"statistic": f"excess kurtosis of shots above the model's (Laplace > 0); Anderson-Darling "
                                   f"k-sample p = {ad:.3g}", "value": float(zk.mean()) if len(zk) else float("nan"),
                      "z": zk_all}
    out["uniform"] = {"statistic": "excess kurtosis of shots below the model's (uniform < 0)",
                      "value": float(zk.mean()) if len(zk) else float("nan"), "z": -zk_all}
    # crosstalk: score in the direction d(mean)/dk of the noiseless forward pass
    out["crosstalk"] = _crosstalk_signature(model, meas, zmean, Ys, Ms)
    ra = cat([h[0] for h in halves])
    rb = cat([h[1] for h in halves])
    rho = float(np.corrcoef(ra, rb)[0, 1]) if len(ra) > 3 else float("nan")
    out["weight_error"] = {"statistic": "split-half reproducibility of mean offsets (correlation of the two halves' "
                                        "standardised residual means)", "value": rho,
                           "z": float(np.arctanh(np.clip(rho, -0.999999, 0.999999)) * np.sqrt(max(len(ra) - 3, 1)))}
    out["saturation"] = {"statistic": "mean residual along -mean^3 (compression at large values)",
                         "value": float("nan"), "z": _score(cat(zmean), cat(wsat))}
    if meas.t is not None:
        out["drift"] = {"statistic": f"mean residual along t * mean (gain 1 + r t); Ljung-Box p in acquisition order "
                                     f"= {_ljung_box(meas, Ys, Ms):.3g}",
                        "value": float("nan"), "z": _score(cat(zmean), cat(wdrift))}
    else:
        out["drift"] = {"statistic": "no acquisition times in the file: drift is silent", "value": float("nan"),
                        "z": float("nan")}
    step = lattice_step(meas)
    out["quantization"] = {"statistic": (f"measured values sit on a lattice of step {step:.4g}" if step else
                                         "measured values are not on a lattice"),
                           "value": float(step) if step else float("nan"), "z": float("nan")}
    for name, s in out.items():
        s["stands_out"] = bool((np.isfinite(s["z"]) and abs(s["z"]) > 3 and
                                (s["z"] > 0 or name in ("crosstalk", "drift")))
                               or (name == "quantization" and step is not None))
    return out


def _crosstalk_signature(model, meas, zmean, Ys, Ms):
    params = model.params if model.params is not None else meas.params
    sigma = meas.arch.sigma
    ids = meas.layer_ids()

    def means(k):
        a = meas.x
        outs = []
        L = len(params)
        for l, (W, b) in enumerate(params, start=1):
            W = np.asarray(W)
            pad = np.pad(W, ((0, 0), (1, 1)))
            z = a @ (W + k * (pad[:, :-2] + pad[:, 2:])).T + np.asarray(b)
            a = np.asarray(sigma(z)) if l < L else z
            outs.append(a)
        return [outs[l - 1] for l in ids]

    h = 1e-3
    dirs = [(p - m) / (2 * h) for p, m in zip(means(h), means(-h))]
    se = [np.sqrt(Y.var(1, ddof=1) / Y.shape[1] + M.var(1, ddof=1) / M.shape[1] + 1e-300) for Y, M in zip(Ys, Ms)]
    w = np.concatenate([np.ravel(d / s) for d, s in zip(dirs, se)])
    e = np.concatenate([np.ravel(z) for z in zmean])
    z = _score(e, w)
    khat = float(np.sum(e * w) / np.sum(w ** 2)) if np.sum(w ** 2) > 0 else float("nan")
    return {"statistic": f"neighbour-weight regression of mean residuals: k_hat = {khat:.3g}", "value": khat, "z": z}


def _anderson(Ys, Ms, m: int = 3000):
    """Anderson-Darling k-sample p of the pooled standardised shots, data against model."""
    rng = np.random.default_rng(0)
    d, s = [], []
    for Y, M in zip(Ys, Ms):
        mm, sm = M.mean(1, keepdims=True), M.std(1, keepdims=True) + 1e-300
        d.append(np.ravel((Y - mm) / sm))
        s.append(np.ravel((M - mm) / sm))
    d, s = np.concatenate(d), np.concatenate(s)
    d = rng.choice(d, min(m, len(d)), replace=False)
    s = rng.choice(s, min(m, len(s)), replace=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(stats.anderson_ksamp([d, s]).pvalue)


def _ljung_box(meas, Ys, Ms, lags: int = 10):
    """Ljung-Box p of the per-input mean residual (standardised, over shots and neurons of
    every measured layer) in acquisition order: independent across inputs under the model."""
    e = 0.0
    for Y, M in zip(Ys, Ms):
        se = np.sqrt(Y.var(1, ddof=1) / Y.shape[1] + M.var(1, ddof=1) / M.shape[1] + 1e-300)
        e = e + ((Y.mean(1) - M.mean(1)) / se).mean(1)
    x = np.asarray(e)[np.argsort(meas.t.mean(1), kind="stable")]
    x = x - x.mean()
    n = len(x)
    lags = min(lags, n - 2)
    if lags < 1:
        return float("nan")
    den = np.sum(x ** 2)
    q = sum((np.sum(x[k:] * x[:-k]) / den) ** 2 / (n - k) for k in range(1, lags + 1)) * n * (n + 2)
    return float(stats.chi2.sf(q, lags))
