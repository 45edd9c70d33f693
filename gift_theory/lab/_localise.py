"""Stage 6 of the lab: where a model fails -- layers, neurons, inputs -- and each effect's signature there.

:class:`Residuals` holds, per measured layer, the measured shots against two disjoint halves
A and B of the model's shots: half A enters every residual, half B every scale and every
direction a residual is projected on, so a residual has mean exactly zero under the model
whatever its scale (a ratio of a variance to its own estimate would be biased). Statistics
are summed per input and tested over inputs (Student t on the normal scale): inputs are
independent, the neurons of one input are not (noise upstream reaches them all).

* :func:`signatures`: each registered effect's own signature statistic
  (:meth:`gift_theory.effects.Effect.signature`), z ~ N(0, 1) under the model;
* :func:`layer_evidence`: per measured layer and neuron, the mean residual and the excess log
  variance against the model's noiseless pre-activation -- a constant offset, a slope or a
  curvature with z, a variance growing with |z| -- the localised evidence that
  :mod:`._mechanisms` turns into mechanism classes;
* :func:`where_it_fails`: per-cell standardised statistics binned over the pre-activation
  (the heatmaps of ``gift diagnose``) and the worst cells.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax.numpy as jnp
import numpy as np
from scipy import stats

from .._measurement import Measurement
from .._model import forward, named_subkey
from ..effects import REGISTRY
from ._shots import Model, model_shots, noiseless_pre, params32


def t_to_z(mean: float, se: float, df: int) -> float:
    """A Student t statistic on the normal scale (two-sided: the sign is kept)."""
    if not np.isfinite(se) or se <= 0:
        return 0.0 if mean == 0 else float(np.sign(mean)) * 40.0
    t = mean / se
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        z = float(stats.norm.isf(stats.t.sf(abs(t), df=df)))
    return float(np.sign(t) * (z if np.isfinite(z) else abs(t)))


def over_inputs(T) -> float:
    """z of the mean of per-input values T (n,) against zero (Student t over inputs)."""
    T = np.asarray(T, np.float64)
    T = T[np.isfinite(T)]
    if T.size < 3:
        return float("nan")
    return t_to_z(float(T.mean()), float(T.std(ddof=1) / np.sqrt(T.size)), T.size - 1)


def _kurt(A):
    c = A - A.mean(1, keepdims=True)
    v = np.mean(c ** 2, 1)
    return np.mean(c ** 4, 1) / np.maximum(v ** 2, 1e-300) - 3.0


@dataclasses.dataclass
class Residuals:
    """Measured shots against a model, per measured layer (lists over layers, each (n, d_l)
    unless said).

    Y, MA, MB : (n, r, d), (n, K/2, d), (n, K/2, d) measured shots and the model's halves
    mean_resid : (md - mA) / sqrt(vB (1/r + 2/K)), ~ N(0, 1) per cell under the model
    var_resid : (vd - vA) / vB, mean zero under the model
    kurt_resid : excess kurtosis of the r measured shots minus that of r model shots (half A,
        averaged over its groups of r): the same estimator at the same size, mean zero
    mB, vB : the model's per-cell mean and variance from half B (scales and directions)
    pre : the model's noiseless pre-activation z_l
    t : (n, r) acquisition times or None
    """

    meas: Measurement
    model: Model
    layer_ids: tuple
    Y: list
    MA: list
    MB: list
    mean_resid: list
    var_resid: list
    kurt_resid: list
    mB: list
    vB: list
    pre: list
    t: np.ndarray | None

    @property
    def n(self) -> int:
        return self.meas.n

    over_inputs = staticmethod(over_inputs)

    def score(self, e, w) -> float:
        """z of the residuals ``e`` projected on the direction ``w`` (lists over layers of (n, d)
        arrays, or one array): per input sum_j e_ij w_ij, tested over inputs."""
        e = e if isinstance(e, list) else [e]
        w = w if isinstance(w, list) else [w]
        T = sum(np.nansum(np.asarray(a) * np.asarray(b), axis=-1) for a, b in zip(e, w))
        return over_inputs(T)

    def mean_derivative(self, effect: str, param: str, at: float, h: float):
        """Per layer (n, d), d(noiseless model mean)/d param of ``effect`` added at ``at``
        (central difference of step h, every draw zero): the direction the effect would move
        the measured means."""
        arch = self.meas.arch
        out = []
        for sign in (1.0, -1.0):
            phys = self.model.physics.with_effect(effect, **{param: at + sign * h})
            noise = {k: jnp.zeros((self.n, 1) + tuple(ev), jnp.float32) for k, ev in phys.draws(arch).items()}
            f = forward(params32(self.model.weights(self.meas)), jnp.asarray(self.meas.x, jnp.float32)[:, None, :],
                        noise, phys, arch, taps=True)
            out.append([np.asarray(f.taps[l - 1][:, 0], np.float64) for l in self.layer_ids])
        return [(p - m) / (2 * h) for p, m in zip(*out)]


def residuals(key, model: Model, meas: Measurement, shots: int | None = None) -> Residuals:
    """The :class:`Residuals` of ``model`` on ``meas`` (model shots K = ``shots``, default 4 r)."""
    Ms = [np.asarray(M, np.float64) for M in model_shots(named_subkey(key, "residual_shots"), model, meas, shots)]
    r = meas.r
    pres = noiseless_pre(model, meas)
    out = {k: [] for k in ("Y", "MA", "MB", "mean_resid", "var_resid", "kurt_resid", "mB", "vB", "pre")}
    for l, M, Y in zip(meas.layer_ids(), Ms, meas.layers()):
        h = M.shape[1] // 2
        MA, MB = M[:, :h], M[:, h:2 * h]
        mA, vA = MA.mean(1), MA.var(1, ddof=1)
        mB, vB = MB.mean(1), MB.var(1, ddof=1)
        md, vd = Y.mean(1), Y.var(1, ddof=1)
        floor = 1e-12 * max(float(np.mean(vB)), 1e-300)
        groups = max(h // r, 1)
        kM = np.mean([_kurt(MA[:, g * r:(g + 1) * r]) for g in range(groups)], axis=0) if h >= r else _kurt(MA)
        out["Y"].append(Y)
        out["MA"].append(MA)
        out["MB"].append(MB)
        out["mean_resid"].append((md - mA) / np.sqrt(vB * (1.0 / r + 1.0 / h) + floor))
        out["var_resid"].append((vd - vA) / (vB + floor))
        out["kurt_resid"].append(_kurt(Y) - kM)
        out["mB"].append(mB)
        out["vB"].append(vB)
        out["pre"].append(pres[l - 1])
    return Residuals(meas, model, meas.layer_ids(), t=meas.t, **out)


def signatures(key, model: Model, meas: Measurement, shots: int | None = None, res: Residuals | None = None) -> dict:
    """Every registered effect's signature statistic in the residuals of ``model``.

    Returns
    -------
    {effect: {"statistic": str, "value": float, "z": float, "stands_out": bool}} for every
    effect that declares one (``stands_out``: z > 3)
    """
    res = res if res is not None else residuals(key, model, meas, shots)
    out = {}
    for name, cls in REGISTRY.items():
        if name in model.effects:
            continue
        sig = cls.signature(res)
        if sig is None:
            continue
        z = float(sig.get("z", float("nan")))
        out[name] = {"statistic": sig["statistic"], "value": float(sig.get("value", float("nan"))), "z": z,
                     "stands_out": bool(sig.get("stands_out", np.isfinite(z) and z > 3.0))}
    return out


# ---- localised evidence for the mechanism rules ----------------------------------------------

def _profile_fit(e, zpre):
    """Per neuron, regress per-input residuals e (n,) on [1, z_c, z_c^2 - mean] (z_c the centred,
    scaled pre-activation): coefficients and their z (OLS with the residual's spread)."""
    n = e.shape[0]
    zc = (zpre - zpre.mean()) / (zpre.std() + 1e-12)
    X = np.stack([np.ones(n), zc, zc ** 2 - np.mean(zc ** 2)], axis=1)
    beta, *_ = np.linalg.lstsq(X, e, rcond=None)
    resid = e - X @ beta
    s2 = float(resid @ resid) / max(n - 3, 1)
    cov = s2 * np.linalg.pinv(X.T @ X)
    return beta, beta / np.sqrt(np.maximum(np.diag(cov), 1e-300))


def layer_evidence(res: Residuals) -> list[dict]:
    """Per measured layer: how its mean residuals and excess variances depend on the model's
    noiseless pre-activation, neuron by neuron, each summarised as a z over the layer.

    Returns one dict per measured layer:
    ``offset_z`` -- chi-square of the per-neuron constant offsets on the normal scale (a
    per-neuron stripe: a bias offset); ``slope_z``, ``curve_z`` -- the same for the per-neuron
    slope and curvature of the mean residual against z (an odd or even distortion of the
    transfer: an activation or readout mismatch); ``common_slope_z`` -- the slope shared by the
    layer's neurons (a gain: every neuron's residual grows with its z the same way);
    ``var_level_z`` -- the mean excess variance over the layer (noise level), ``var_abs_z`` --
    excess variance along |z - median| (signal-dependent noise), ``kurt_z`` -- excess
    kurtosis (noise law), ``time_z`` -- mean residual along acquisition time (drift).
    """
    out = []
    for li, l in enumerate(res.layer_ids):
        e, v, k, zpre = res.mean_resid[li], res.var_resid[li], res.kurt_resid[li], res.pre[li]
        n, d = e.shape
        coefs = np.array([_profile_fit(e[:, j], zpre[:, j])[1] for j in range(d)])  # (d, 3) z's
        betas = np.array([_profile_fit(e[:, j], zpre[:, j])[0] for j in range(d)])

        def chi_z(zs):
            q = float(np.sum(zs ** 2))
            return float(stats.norm.isf(max(stats.chi2.sf(q, df=len(zs)), 1e-300)))

        zc = (zpre - zpre.mean(0)) / (zpre.std(0) + 1e-12)
        absz = np.abs(zc) - np.mean(np.abs(zc), axis=0)
        row = {"layer": int(l), "neurons": int(d),
               "offset_z": chi_z(coefs[:, 0]), "slope_z": chi_z(coefs[:, 1]), "curve_z": chi_z(coefs[:, 2]),
               "common_slope_z": over_inputs(np.sum(e * zc, axis=1)),
               "common_curve_z": over_inputs(np.sum(e * (zc ** 2 - np.mean(zc ** 2, 0)), axis=1)),
               "var_level_z": over_inputs(np.sum(v, axis=1)),
               "var_abs_z": over_inputs(np.sum(v * absz, axis=1)),
               "kurt_z": over_inputs(np.sum(k, axis=1)),
               "offsets": betas[:, 0].tolist()}
        if res.t is not None:
            tc = res.t.mean(1) - res.t.mean()
            row["time_z"] = over_inputs(tc * np.sum(e * np.sign(res.mB[li] + 1e-300), axis=1))
        out.append(row)
    return out


# ---- heatmaps ---------------------------------------------------------------------------------

def where_it_fails(key, model: Model, meas: Measurement, bins: int = 6, shots: int | None = None,
                   res: Residuals | None = None) -> dict:
    """Per-cell standardised statistics, binned over the model's noiseless pre-activation (rows
    ``layer:neuron``, a bin holds ``sum z / sqrt(count)``, N(0, 1) under the model), and the
    worst cells.

    Returns
    -------
    dict with ``rows`` (list of "layer:neuron"), ``maps`` ({statistic: (rows, bins) array}),
    ``worst`` (list of {layer, neuron, input, statistic, z}, worst first)
    """
    res = res if res is not None else residuals(key, model, meas, shots)
    r = meas.r
    names = ["mean_z", "log_var_ratio", "excess_kurtosis"] + (["time_trend"] if meas.t is not None else [])
    rows, maps, worst = [], {k: [] for k in names}, []
    for li, l in enumerate(res.layer_ids):
        Y, MB = res.Y[li], res.MB[li]
        K2 = MB.shape[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            lvr = np.log(np.maximum(Y.var(1, ddof=1), 1e-300) / np.maximum(res.vB[li], 1e-300))
        cell = {"mean_z": res.mean_resid[li],
                "log_var_ratio": lvr / np.sqrt(2 / (r - 1) + 2 / (K2 - 1)),
                "excess_kurtosis": res.kurt_resid[li] / np.sqrt(24 / r + 24 / r)}
        if meas.t is not None:
            resid = (Y - res.mB[li][:, None, :]) / np.sqrt(res.vB[li][:, None, :] + 1e-300)
            tc = meas.t - meas.t.mean()
            cell["time_trend"] = np.einsum("nr,nrd->nd", tc, resid) / np.sqrt(np.sum(tc ** 2, 1) + 1e-300)[:, None]
        pre = res.pre[li]
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
        for name in ("mean_z", "log_var_ratio"):
            v = cell[name]
            for f in np.argsort(-np.abs(np.nan_to_num(v)), axis=None)[:10]:
                i, j = np.unravel_index(f, v.shape)
                worst.append({"layer": int(l), "neuron": int(j), "input": int(i), "statistic": name, "z": float(v[i, j])})
    worst.sort(key=lambda w: -abs(w["z"]))
    return {"rows": rows, "maps": {k: np.array(v) for k, v in maps.items()}, "worst": worst}


def anderson_p(res: Residuals, m: int = 3000) -> float:
    """Anderson-Darling k-sample p of the pooled standardised shots, data against model."""
    rng = np.random.default_rng(0)
    d, s = [], []
    for Y, M, mB, vB in zip(res.Y, res.MA, res.mB, res.vB):
        sd = np.sqrt(vB)[:, None, :] + 1e-300
        d.append(np.ravel((Y - mB[:, None, :]) / sd))
        s.append(np.ravel((M - mB[:, None, :]) / sd))
    d, s = np.concatenate(d), np.concatenate(s)
    d = rng.choice(d, min(m, len(d)), replace=False)
    s = rng.choice(s, min(m, len(s)), replace=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(stats.anderson_ksamp([d, s]).pvalue)
