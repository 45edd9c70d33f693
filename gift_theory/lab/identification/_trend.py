"""Straight-line trends of a layer over acquisition time: within the inputs' shots (interleaved
acquisition; additive or a gain) and of the map across the inputs' mean times, this one
against the inputs' own scatter too."""

from __future__ import annotations

import numpy as np
from scipy import stats

from .._level import ALPHA
from ._layers import _Layer
from ._stats import _within

#: a gain trend in time that carries less than this share of the gain's variance within the
#: inputs' shots is the path of a fluctuating gain, not a drift
TREND_SHARE = 0.5


def _within_trend(lay: _Layer, Ew, g, t, obs):
    """The trend in acquisition time read within the inputs' shots (interleaved acquisition), as
    a known term of each shot's pre-activation: ``(offset (n, r, d), kind, se)`` or None when no
    trend is significant. Two readings: an additive trend per neuron c_i (against
    ``g (t - mean t)``, Bonferroni over the neurons at :data:`ALPHA`) and one relative gain trend
    k on the weighted sum (against ``g u (t - mean t)``, u = W a: the drift effect's 1 + r t),
    each also tested beyond the other: both needed, both are put in (``kind`` "gain"); the gain
    alone when the additive trends add nothing to it; else the additive ones. ``se``: the error
    the trend puts into the map at t = 0 -- its standard error times the inputs' mean time, on
    each neuron's bias (additive, (d,)) or on a common gain of W ("gain", a scalar)."""
    if t is None or Ew.shape[1] < 3:
        return None
    t = np.asarray(t, np.float64)
    tw = t - t.mean(1, keepdims=True)
    if np.std(tw) == 0:
        return None
    d = Ew.shape[2]
    u = lay.A @ lay.W.T  # (n, r or 1, d) the weighted sum

    def within(X):  # the within-input part along each shot's own input removed (Frisch-Waugh)
        X = _within(X, g, lay.A)
        return X - X.mean(1, keepdims=True)

    # an additive trend's column per neuron, a relative gain trend's (shared by the neurons);
    # with taps the input drifts too, and the regression on it that _within removes would take
    # part of a trend with it if done apart (a gain drift of -0.3 read as -0.1 at layer 3)
    Ed = Ew - Ew.mean(1, keepdims=True)  # ``Ew``: the residuals with that part already removed
    D, Dg = within(g * tw[:, :, None]), within(g * u * tw[:, :, None])
    S = np.sum(D * D, axis=(0, 1))
    DD = np.sum(D * D, axis=1)

    def additive(R):  # per neuron c, its z, Bonferroni p
        c = np.sum(D * R, axis=(0, 1)) / np.maximum(S, 1e-300)
        se = np.sqrt(np.sum(DD * obs, axis=0)) / np.maximum(S, 1e-300)
        zc = c / np.maximum(se, 1e-300)
        return c, se, min(1.0, d * 2.0 * float(stats.norm.sf(np.max(np.abs(zc)))))

    def gain(X, R):  # shared k, its se, two-sided p
        Sx = float(np.sum(X * X))
        k = float(np.sum(X * R)) / max(Sx, 1e-300)
        k_se = float(np.sqrt(np.sum(np.sum(X * X, axis=1) * obs))) / max(Sx, 1e-300)
        return k, k_se, 2.0 * float(stats.norm.sf(abs(k) / max(k_se, 1e-300)))

    c, se, p_add = additive(Ed)
    k, k_se, p_gain = gain(Dg, Ed)
    if min(p_add, p_gain) >= ALPHA:
        return None
    # nested: the gain beyond per-neuron additive trends (its column with theirs projected out),
    # and the additive trends beyond the gain; a gain drift (the drift effect's 1 + r t) moves each
    # neuron's mean too, and an additive one is not along the signal
    Dg_perp = Dg - D * (np.sum(D * Dg, axis=(0, 1)) / np.maximum(S, 1e-300))
    k2, k2_se, p_gain_beyond = gain(Dg_perp, Ed)
    p_add_beyond = additive(Ed - k * Dg)[2]
    tbar = float(np.mean(t))
    T = t[:, :, None]
    if p_gain_beyond < ALPHA and p_add_beyond < ALPHA:  # both: jointly
        cj = np.sum(D * (Ed - k2 * Dg), axis=(0, 1)) / np.maximum(S, 1e-300)
        return T * (cj + k2 * u), "gain", tbar * k2_se
    if p_gain < ALPHA and (p_add_beyond >= ALPHA or p_add >= ALPHA):
        return T * k * u, "gain", tbar * k_se
    return T * c[None, None, :], "additive", tbar * se


def _robust_trend_p(X, ebar, alive, p: int, theta) -> float:
    """p of the map's time trends (columns p + 1, p + 2 of each neuron's design ``X`` (n, d, k))
    by a score test whose covariance is the inputs' own scatter, not the noise's: each input's
    contribution to the trends' score at the map fitted without them (the restricted residual
    ``ebar + T~ theta_T``, T~ the trend columns with the map's projected out) is one draw, and
    Hotelling's T^2 over the inputs (F law) tests their mean -- valid for any misfit of the mean
    that does not go with the acquisition order. Jointly over the alive neurons when the inputs
    outnumber the trends three times, else per neuron (Bonferroni); and a gain trend shared by
    the neurons on its own (Bonferroni over the two)."""
    alive = np.asarray(alive, int)
    n = X.shape[0]
    if alive.size == 0 or n < 8:
        return 1.0
    N, T = X[:, alive, :p + 1], X[:, alive, p + 1:p + 3]
    G = np.linalg.pinv(np.einsum("nia,nib->iab", N, N))
    Tt = T - np.einsum("nia,iab->nib", N, G @ np.einsum("nia,nic->iac", N, T))
    er = ebar[:, alive] + np.einsum("nic,ic->ni", Tt, theta[alive][:, p + 1:p + 3])
    Psi = Tt * er[:, :, None]  # (n, da, 2)

    def hotelling(P):  # (n, q) -> p of a zero mean
        q = P.shape[1]
        m = P.mean(0)
        S = np.cov(P, rowvar=False).reshape(q, q)
        w, Q = np.linalg.eigh(S)
        keep = w > 1e-12 * max(float(w.max()), 1e-300)
        q = int(keep.sum())
        if q == 0 or n - q < 1:
            return 1.0
        t2 = n * float(np.sum((Q[:, keep].T @ m) ** 2 / w[keep]))
        return float(stats.f.sf(t2 * (n - q) / (q * (n - 1)), q, n - q))

    da = alive.size
    joint = (hotelling(Psi.reshape(n, 2 * da)) if 3 * 2 * da <= n
             else float(min(1.0, da * min(hotelling(Psi[:, i]) for i in range(da)))))
    # and one gain trend shared by the neurons (the drift effect's 1 + r t): their gain scores summed
    common = hotelling(Psi[:, :, 1].sum(1, keepdims=True))
    return float(min(1.0, 2.0 * min(joint, common)))
