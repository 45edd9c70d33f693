"""The mean map of a layer: its fit, the score test of the programmed map, the shape of z
shared by the neurons, the restricted maps (gain, biases, transfer, per-neuron gains) and a
detector's gain and offset after the activation."""

from __future__ import annotations

import numpy as np
from scipy import stats

from .._smoothing import smoothed
from ._layers import BINS, _Layer, _mean_model, _unit_var
from ._stats import FULL_COV_MAX, _cell_var, _chi2, _gram, _meat, _z_of_p

#: the smooth part of the shared shape the map is tested against (Legendre degree, besides the bins)
SHAPE_DEGREE = 7


def _design(lay: _Layer, g, tt):
    """Per input and neuron, the mean over shots of the linearised design (n, d, k): the slope
    times [a, 1] and, with times, [t, t W a]."""
    A1 = np.concatenate([lay.A, np.ones(lay.A.shape[:2] + (1,))], axis=2)
    K = g.shape[1]
    if A1.shape[1] == 1:  # one regressor per input: the mean slope times it
        X = g.mean(1)[:, :, None] * A1
    else:
        X = np.matmul(g.transpose(0, 2, 1), A1) / K
    if tt is None:
        return X
    u = lay.A @ lay.W.T
    cols = [np.einsum("nki,nk->ni", g, tt) / K, np.einsum("nki,nk->ni", g * u, tt) / K]
    return np.concatenate([X, np.stack(cols, axis=-1)], axis=2)


def _fit_map(lay: _Layer, act: str, s2: float, tt=None, iters: int = 40, W0=None, b0=None):
    """Levenberg-Marquardt on the per-input means, neuron by neuron (each neuron's loss is its
    own): W_eff, b_eff (and the time trends) and what the tests read. A step that does not lower
    a neuron's loss is refused and that neuron's damping raised (a saturated neuron's Jacobian
    is nearly singular: undamped Gauss-Newton runs away there, e.g. on heater crosstalk that
    scrambles W)."""
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    k = p + 1 + (2 if tt is not None else 0)
    th = np.zeros((d, k))
    th[:, :p] = lay.W if W0 is None else W0
    th[:, p] = lay.b if b0 is None else b0
    Ybar = lay.Y.mean(1)

    def evaluate(th):
        drift = None if tt is None else (th[:, p + 1], th[:, p + 2])
        z, m, g, _ = _mean_model(lay, act, th[:, :p], th[:, p], s2, _unit_var(lay, th[:, :p]), tt, drift,
                                 want_var=False)
        e = Ybar - m.mean(1)
        return e, g

    e, g = evaluate(th)
    loss = np.sum(e * e, 0)
    mu = np.full(d, 1e-6)
    for _ in range(iters):
        X = _design(lay, g, tt)
        B = _gram(X)
        dg = np.einsum("ipp->ip", B)
        A = B + (mu[:, None] * np.maximum(dg, 1e-12 * np.max(dg)))[:, :, None] * np.eye(k) + 1e-12 * np.eye(k)
        Xte = np.einsum("nip,ni->ip", X, e)
        step = np.linalg.solve(A, Xte[..., None])[..., 0]
        new = th + step
        e_n, g_n = evaluate(new)
        loss_n = np.sum(e_n * e_n, 0)
        ok = loss_n <= loss
        th = np.where(ok[:, None], new, th)
        e = np.where(ok[None, :], e_n, e)
        g = np.where(ok[None, None, :], g_n, g) if g_n.shape == g.shape else g_n
        loss = np.where(ok, loss_n, loss)
        mu = np.where(ok, np.maximum(mu / 10.0, 1e-9), mu * 10.0)
        # a neuron has converged when its last step -- taken or refused -- is below the
        # tolerance, or would lower its loss (the squared misfit of its n means, at the optimum
        # n times a mean's noise variance) by less than 1e-10 of it: near the minimum the
        # design (the slope at each shot) is not the loss's exact Jacobian, steps of ~1e-5
        # of W are refused as often as taken and raise the damping without end, so the
        # damping is no stopping criterion
        small = np.max(np.abs(step), 1) < 1e-7 * (1 + np.max(np.abs(th[:, :p]), 1))
        flat = np.einsum("ip,ip->i", step, Xte) <= 1e-8 * np.maximum(loss, 1e-300)
        if np.all(small | flat):
            break
    W, b = th[:, :p], th[:, p]
    drift = None if tt is None else (th[:, p + 1], th[:, p + 2])
    z, m, g, var = _mean_model(lay, act, W, b, s2, _unit_var(lay, W), tt, drift)
    X = _design(lay, g, tt)
    E = lay.Y - m  # (n, r, d) residual per shot (each shot against the mean at its own regressor)
    return W, b, drift, z, m, g, var, X, E


def _trends_free(X, p: int):
    """The design's map columns (n, d, p + 1) and ``off``, which projects per-neuron arrays --
    (n, d) residual means or (n, d, c) designs -- off its time-trend columns (the trends free)."""
    XT = X[:, :, p + 1:]
    Gi = np.linalg.inv(np.einsum("nia,nib->iab", XT, XT) + 1e-12 * np.eye(XT.shape[2]))

    def off(v):
        if v.ndim == 2:
            return v - np.einsum("nia,ia->ni", XT, np.einsum("iab,ib->ia", Gi, np.einsum("nib,ni->ib", XT, v)))
        return v - np.einsum("nia,iac->nic", XT, Gi @ np.einsum("nib,nic->ibc", XT, v))

    return X[:, :, :p + 1], off


def _score_omnibus(lay: _Layer, act: str, s2: float, tt, Chat, obs, r: float, alive, nu: float):
    """(p, z) of the programmed map (W, b; the time trends free) by a score test at it: each
    neuron's per-input mean residual at the programmed map, projected on its design there,
    against the covariance of those means (the within-input shots' over ``r``). Jointly across
    the neurons with their covariance where the layer is small enough for it; else per neuron,
    the largest Bonferroni-corrected (neurons of one input share noise: a sum of their
    statistics would not be a chi-square)."""
    n, _, d = lay.Y.shape
    p = lay.W.shape[1]
    drift0 = None if tt is None else (np.zeros(d), np.zeros(d))
    _, m0, g0, _ = _mean_model(lay, act, lay.W, lay.b, s2, _unit_var(lay, lay.W), tt, drift0, want_var=False)
    e = lay.Y.mean(1) - m0.mean(1)  # (n, d)
    X = _design(lay, g0, tt)
    P = None if lay.memory is None else lay.memory[0]  # alpha's error moves the means along P
    if tt is not None:  # the trends free: both the residual and the design projected off them
        X, off = _trends_free(X, p)
        e, P, X = off(e), (None if P is None else off(P)), off(X)
    alive = np.asarray(alive, int)
    if alive.size == 0:
        return 1.0, 0.0
    e, X = e[:, alive], X[:, alive]
    da, kk = X.shape[1], X.shape[2]
    U = np.einsum("nip,ni->ip", X, e)
    wm = None if P is None else lay.memory[1] * np.einsum("nip,ni->ip", X, P[:, alive])
    if Chat is not None and da * kk <= FULL_COV_MAX:
        Ca = Chat[:, alive][:, :, alive]
        V = _meat(Ca / r, X).reshape(da * kk, da * kk)
        if wm is not None:
            V = V + np.outer(wm.ravel(), wm.ravel())
        w, Q = np.linalg.eigh(V)
        keep = w > 1e-10 * max(w.max(), 1e-300)
        q = float(np.sum((Q[:, keep].T @ U.ravel()) ** 2 / w[keep]))
        return _chi2(q, int(keep.sum()), nu)
    ps = np.empty(da)
    for a_, i in enumerate(alive):
        Xi = X[:, a_]
        Vi = Xi.T @ (Xi * (obs[:, i] / r)[:, None])
        w, Q = np.linalg.eigh(Vi if wm is None else Vi + np.outer(wm[a_], wm[a_]))
        keep = w > 1e-10 * max(w.max(), 1e-300)
        ps[a_] = _chi2(float(np.sum((Q[:, keep].T @ U[a_]) ** 2 / w[keep])), int(keep.sum()), nu)[0]
    pmin = float(min(1.0, da * ps.min()))
    return pmin, (_z_of_p(pmin) if pmin < 1.0 else 0.0)


def _bin_shares(zref, z):
    """The :data:`BINS` quantile bins of ``zref`` (outer edges open) and, per input and neuron,
    the share of ``z``'s shots (n, r, d) in each bin (n, d, BINS)."""
    edges = np.quantile(zref, np.linspace(0, 1, BINS + 1))
    edges[0], edges[-1] = -np.inf, np.inf
    idxb = np.clip(np.searchsorted(edges, z, side="right") - 1, 0, BINS - 1)
    return edges, np.stack([(idxb == j).mean(1) for j in range(BINS)], axis=-1)


def _score_given_shape(lay: _Layer, act: str, s2: float, tt, Chat, r: float, alive, nu: float) -> float:
    """p of the programmed map (W, b; time trends free) by a score test *given* a function of z
    shared by the layer's neurons (the shape test's bins at the programmed z and a polynomial of
    degree SHAPE_DEGREE, one coefficient each for the whole layer, profiled out): does the map deviate beyond what a
    transfer that is not the programmed activation explains? Jointly over the alive neurons
    with their covariance (the layer small enough for it)."""
    n, _, d = lay.Y.shape
    p = lay.W.shape[1]
    drift0 = None if tt is None else (np.zeros(d), np.zeros(d))
    z0, m0, g0, _ = _mean_model(lay, act, lay.W, lay.b, s2, _unit_var(lay, lay.W), tt, drift0, want_var=False)
    e = lay.Y.mean(1) - m0.mean(1)
    X = _design(lay, g0, tt)
    alive = np.asarray(alive, int)
    zz = z0[:, :, alive]
    Hb = _bin_shares(zz, zz)[1]
    # the shape: the bins of the shape test, and a smooth part (Legendre polynomials of degree
    # 1 to SHAPE_DEGREE in z scaled to [-1, 1]): bins alone leave the within-bin slope of a smooth transfer
    # (tanh + a tanh^2, sin) in the residual, which the map's design picks up at 240 x 32 shots
    u = zz / max(float(np.max(np.abs(zz))), 1e-300)
    poly = np.polynomial.legendre.legvander(u, SHAPE_DEGREE)[..., 1:]  # (n, r, da, SHAPE_DEGREE)
    H = np.concatenate([Hb, poly.mean(1)], axis=-1)  # (n, da, B + SHAPE_DEGREE)
    e, X = e[:, alive], X[:, alive]
    P = None if lay.memory is None else lay.memory[0][:, alive]  # alpha's error moves the means along P
    da, k = X.shape[1], X.shape[2]
    if tt is not None:  # the time trends are nuisance parameters too, per neuron (as in the omnibus)
        X, off = _trends_free(X, p)
        e, P, X, H = off(e), (None if P is None else off(P)), off(X), off(H)
        k = X.shape[2]
    # stacked over (input, neuron): the map's design B is block-diagonal over neurons (neuron i's
    # row of input n is X[n, i] in its own block), the shape's columns H are shared; both are
    # projected off the shape's span, B' = B - H G with G = (H'H)^+ H'B of rank <= the shape's
    # columns, so the score's covariance sum_n B'_n^T C_n B'_n is the sandwich meat of B plus
    # low-rank terms (never the dense (n da) x (da k) design)
    Hs = H.reshape(n * da, -1)
    Pi = np.linalg.pinv(Hs.T @ Hs)
    G = Pi @ np.einsum("nib,nik->bik", H, X).reshape(H.shape[2], da * k)  # (c, da k)

    def score(v):  # the score of residual means v (n, da), the shape profiled out
        vs = v - H @ (Pi @ (Hs.T @ v.reshape(-1)))
        return np.einsum("nik,ni->ik", X, vs).reshape(-1) - G.T @ (Hs.T @ vs.reshape(-1))

    U = score(e)
    Ca = Chat[:, alive][:, :, alive] / r
    CH = np.matmul(Ca, H)  # (n, da, c)
    HCB = np.einsum("nic,nik->cik", CH, X).reshape(H.shape[2], da * k)  # sum_n H_n^T C_n B_n
    HCH = np.einsum("nic,nid->cd", H, CH)
    V = (_meat(Ca, X).reshape(da * k, da * k) - G.T @ HCB - HCB.T @ G + G.T @ HCH @ G)
    if P is not None:
        wm = score(P)
        V = V + lay.memory[1] ** 2 * np.outer(wm, wm)
    w, Q = np.linalg.eigh(V)
    keep = w > 1e-10 * max(w.max(), 1e-300)
    q = float(np.sum((Q[:, keep].T @ U) ** 2 / w[keep]))
    return _chi2(q, int(keep.sum()), nu)[0]


def _map_uncertainty(lay: _Layer, act: str, s_guess: float) -> float:
    """The map's standard error against its own size, at the programmed map: per neuron the rms
    standard error of its row of W (the per-input means' least squares, weighted by their
    shots' variance) over the row's rms, the median over the layer's neurons (without taps, at
    least the regressor's Monte Carlo error over its spread across inputs). Above 1 the mean
    response carries no more about W_eff than noise (a saturated layer at s = 10: its least
    squares wandered to |z| ~ 1e7 along a flat valley, and its shape tests named
    activation_mismatch on correctly specified files)."""
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    s2 = s_guess ** 2
    z, m, g, var = _mean_model(lay, act, lay.W, lay.b, s2, _unit_var(lay, lay.W), want_var=False)
    X = _design(lay, g, None)  # (n, d, p + 1)
    w = r / (lay.mean_factor * _cell_var(lay.Y - m, lay.res_var))
    F = np.einsum("nia,ni,nib->iab", X, w, X)
    se = np.sqrt(np.maximum(np.einsum("iaa->ia", np.linalg.pinv(F, hermitian=True))[:, :p], 0.0))
    rms_w = np.sqrt(np.mean(lay.W ** 2, axis=1))
    ratio = float(np.median(np.sqrt(np.mean(se ** 2, axis=1)) / np.maximum(rms_w, np.finfo(np.float64).tiny)))
    if lay.draws and lay.Cin is not None and lay.Cin.ndim == 3:
        # without taps the regressor is a Monte Carlo mean of the layer before: where its error
        # across inputs exceeds its spread, the least squares fits the draws' noise, and its slope
        # shrinks towards 0 (s = 10: W_eff = 0.03 W, "gain_error" on a correctly specified file)
        mc = s2 * float(np.mean(np.einsum("nii->ni", lay.Cin))) / lay.draws
        spread = float(np.mean(np.var(lay.A[:, 0, :], axis=0)))
        ratio = max(ratio, float(np.sqrt(mc / max(spread, np.finfo(np.float64).tiny))))
    return ratio


def _shape_given_detector(rows: list, p_shape: float):
    """The shape test's row, when its layer's neurons have a detector's gain and offset: its
    p-value is the test's on the detector's residual (no smaller than before: a detector's
    g_i sigma(z) + o_i is not affine in z, and the neurons' mean gain left a shared shape that
    named activation_mismatch beside the detector)."""
    for rw in rows:
        if rw["test"] == "shape":
            rw["p"] = max(rw["p"], p_shape)
            rw["z"] = _z_of_p(rw["p"]) if rw["p"] < 1.0 else 0.0
            rw["evidence"] += f"; given each neuron's detector gain and offset, p = {p_shape:.2g}"


def _detector_or_modulator(lay: _Layer, act: str, s2: float, obs, mf: float, alive, tt=None, iters: int = 8):
    """Where a hidden layer's per-neuron gains and offsets sit: on z, a modulator's
    ``sigma(g_i z + o_i)``, or on the layer's output, a detector's ``g_i sigma(z) + o_i`` (the
    readout chain D of reference §2; a tap measures what it gives). Near z = 0 the two agree;
    where the activation bends they do not (detectors on every layer of a tapped chip were named
    activation_mismatch, the modulator's class).

    Both are fitted neuron by neuron to the per-input means at the programmed map, two
    parameters each (least squares for the detector, Gauss-Newton for the modulator).

    Returns
    -------
    (Q_detector, Q_modulator, Q_programmed, p_shape, p_time) : each Q the weighted sum of squared
        residuals over the alive neurons (weights: the per-input means' inverse variances),
        Q_programmed the programmed map's; p_shape the shape test's p-value on the detector's
        residual (a function of z shared by the neurons beyond their detectors); p_time the test
        of a trend over the inputs' mean times ``tt`` left in it (1 without times: the map's own
        time test reads a map of z, which a detector is not)
    """
    n, r, _ = lay.Y.shape
    vu = _unit_var(lay, lay.W)
    z = lay.A @ lay.W.T + lay.b
    if lay.offset is not None:
        z = z + lay.offset
    z, vz = z[:, :, alive], (s2 * vu[:, None, :])[:, :, alive]
    Ybar = lay.Y.mean(1)[:, alive]
    # the per-input means' inverse variances, from r shots each: 1 / (a chi^2 on r - 1 df) is
    # biased up by (r - 1) / (r - 3), which inflated Q by 15 % at 16 shots
    w = r / (mf * np.maximum(obs[:, alive], 1e-300)) * (max(r - 3, 1) / max(r - 1, 1))  # (n, da)
    m0 = smoothed(act, z, np.broadcast_to(vz, z.shape), var=False)[0].mean(1)

    def wls(cols, y):  # per neuron: weighted least squares of y on cols (n, da, c)
        F = np.einsum("nic,ni,nid->icd", cols, w, cols)
        b = np.einsum("nic,ni,ni->ic", cols, w, y)
        return np.linalg.solve(F + 1e-12 * np.eye(cols.shape[2]), b[..., None])[..., 0]

    det = np.stack([m0, np.ones_like(m0)], -1)
    e_det = Ybar - np.einsum("nic,ic->ni", det, wls(det, Ybar))
    # the shape of z shared by the neurons that the detector's residual still has (the shape
    # test's, given the detector): its bins' shares less each neuron's detector columns
    H = _bin_shares(z, z)[1]  # (n, da, B)
    H = H - np.einsum("nic,icb->nib", det, np.stack([wls(det, H[:, :, j]) for j in range(H.shape[2])], -1))
    S = np.einsum("ni,ni,nib->b", w, e_det, H)
    V = np.einsum("ni,nib,nic->bc", w, H, H)
    ev, U = np.linalg.eigh(V)
    keep = ev > 1e-9 * max(ev.max(), 1e-300)
    q_shape = float(np.sum((U[:, keep].T @ S) ** 2 / ev[keep]))
    p_shape = float(stats.chi2.sf(q_shape, int(keep.sum())))
    # a trend in the inputs' acquisition times left in the detector's residual (per neuron)
    p_time = 1.0
    if tt is not None:
        tc = np.broadcast_to((tt[:, 0] - tt.mean())[:, None], m0.shape)
        tc = tc - np.einsum("nic,ic->ni", det, wls(det, tc))
        q_t = float(np.sum(np.einsum("ni,ni,ni->i", w, e_det, tc) ** 2 / np.maximum(np.einsum("ni,ni->i", w, tc * tc),
                                                                                     1e-300)))
        p_time = float(stats.chi2.sf(q_t, len(alive)))
    gg, oo = np.ones(len(alive)), np.zeros(len(alive))
    for _ in range(iters):
        zz = gg * z + oo
        m, g = smoothed(act, zz, np.broadcast_to(vz, z.shape), var=False)[:2]
        e = Ybar - m.mean(1)
        J = np.stack([(g * z).mean(1), g.mean(1)], -1)
        step = wls(J, e)
        gg, oo = gg + step[:, 0], oo + step[:, 1]
    m = smoothed(act, gg * z + oo, np.broadcast_to(vz, z.shape), var=False)[0]
    e_mod = Ybar - m.mean(1)
    return (float(np.sum(w * e_det ** 2)), float(np.sum(w * e_mod ** 2)), float(np.sum(w * (Ybar - m0) ** 2)),
            p_shape, p_time)
