"""Each layer's realised map read off a measurement, shrunk towards the programmed one where the
data cannot see it (empirical-Bayes ridge).

A layer l of the chip realises some map (W_eff, b_eff) of what was programmed (W, b)
(docs/reference.md §2: u = W_eff a, z = g u + b_eff + n_w, a_l = sigma(z) + n_a). With taps,
its measured output is regressed on the measured input of the same shot (layer 1: on x); without
taps, the output layer on the model's mean of a_{L-1} (the hidden layers taken as programmed).
Per neuron i, the per-input mean output is modelled as the mean over the shots of
sigma~(theta_i . [a, 1]) (sigma~: the activation smoothed by the pre-activation's noise,
:func:`gift_theory.lab.smoothed`; the identity at the output layer), theta_i = (w_i, b_i).

A calibration programs the difference between a target and this fit, so an entry the data do
not determine must not be read as a deviation: on a layer fed by inputs that never vary (the
digits' border pixels), or by saturated neurons (tanh' ~ 0), least squares returns arbitrary
values there, and programming them would wreck the chip. The fit is therefore a posterior mean
under the prior theta_i ~ N(theta_prog_i, diag(tau_W^2 I, tau_b^2)): the deviation from the
programmed map is zero unless the data show it. tau_W and tau_b (one pair per layer) maximise
the marginal likelihood of the per-input means (type-II maximum likelihood, at the programmed
map's linearisation); the posterior mean is found by Gauss-Newton on the penalised least squares
(steps that do not lower it are halved). Each mean's noise variance is its neuron's pooled
within-input variance over the r shots.

All numpy float64, every neuron at once (batched (d, k, k) algebra).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import optimize

from .._measurement import Measurement


@dataclasses.dataclass(frozen=True)
class LayerMap:
    """One layer's realised map.

    layer : 1-based
    W, b : (d, p), (d,) the posterior mean of the realised map
    W_se, b_se : (d, p), (d,) its posterior standard deviations
    W_prog, b_prog : the programmed map the fit was centred on
    s : the layer's additive noise level read off the within-input spread
    tau_W, tau_b : the prior's scales (empirical Bayes)
    inputs, shots : the data it was read from
    inputs_seen : (n, r', p) the layer's measured inputs (r' = 1: one per input); ``hidden``:
        whether the activation follows (what a correction of the map acts on: a change along a
        direction the inputs never take does nothing on the data)
    """

    layer: int
    W: np.ndarray
    b: np.ndarray
    W_se: np.ndarray
    b_se: np.ndarray
    W_prog: np.ndarray
    b_prog: np.ndarray
    s: float
    tau_W: float
    tau_b: float
    inputs: int
    shots: int
    inputs_seen: np.ndarray
    hidden: bool

    def deviation_z(self):
        """(d, p), (d,): the realised map's deviation from the programmed one in standard errors."""
        return (self.W - self.W_prog) / self.W_se, (self.b - self.b_prog) / self.b_se


def _unit_var(data, W):
    """(n, d): the pre-activation noise variance per s^2 (the lab's, on this fit's data)."""
    from ..lab._identify import _unit_var as unit_var
    return unit_var(data, W)


def _activation(name: str):
    from ..lab._identify import smoothed  # the lab's smoothed activation (Gauss-Hermite)
    return lambda z, v: smoothed(name, z, v, var=True)


@dataclasses.dataclass(frozen=True)
class _Data:
    A: np.ndarray          # (n, r, p) or (n, 1, p): the regressor of each shot
    Y: np.ndarray          # (n, r, d)
    Cin: np.ndarray | None  # None, (p, p) or (n, p, p): unit covariance of the unmeasured input noise
    hidden: bool


def _mean_model(data: _Data, act, th, s2):
    """Per input the model's mean output (n, d), design (n, d, k) and per shot the model's
    variance (n, r', d) at theta (d, k)."""
    W, b = th[:, :-1], th[:, -1]
    z = data.A @ W.T + b                                  # (n, r', d)
    vz = s2 * _unit_var(data, W)[:, None, :]
    if data.hidden:
        m, g, var = act(z, np.broadcast_to(vz, z.shape))
        var = var + s2
    else:
        m, g, var = z, np.ones_like(z), np.broadcast_to(vz, z.shape)
    A1 = np.concatenate([data.A, np.ones(data.A.shape[:2] + (1,))], axis=2)
    X = np.matmul(g.transpose(0, 2, 1), A1) / g.shape[1]   # (n, d, k): mean over shots of g [a, 1]
    return m.mean(1), X, var


def _noise_level(data: _Data, act, th, s2):
    """s^2 such that the model's within-input variance matches the measured one (fixed point)."""
    r = data.Y.shape[1]
    if r < 2:
        return s2
    W, b = th[:, :-1], th[:, -1]
    if data.A.shape[1] == r:  # taps: each shot against the mean at its own regressor
        z = data.A @ W.T + b
        for _ in range(8):
            vz = s2 * _unit_var(data, W)[:, None, :]
            if data.hidden:
                m, _, var = act(z, np.broadcast_to(vz, z.shape))
                var = var + s2
            else:
                m, var = z, np.broadcast_to(vz, z.shape)
            obs = np.var(data.Y - m, axis=1, ddof=1)
            mod = var.mean(1)
            new = s2 * float(np.mean(obs) / max(np.mean(mod), 1e-300))
            if abs(new / s2 - 1.0) < 1e-4:
                return new
            s2 = new
        return s2
    obs = float(np.mean(np.var(data.Y, axis=1, ddof=1)))
    for _ in range(8):
        _, _, var = _mean_model(data, act, th, s2)
        new = s2 * obs / max(float(np.mean(var)), 1e-300)
        if abs(new / s2 - 1.0) < 1e-4:
            return new
        s2 = new
    return s2


def _evidence(log_t, G, c0, nu):
    """-2 log marginal likelihood (summed over neurons, constants dropped) of e = X delta + noise,
    delta ~ N(0, diag(tau_W^2, .., tau_b^2)), noise ~ N(0, nu_i) per neuron; log_t = (log tau_W^2,
    log tau_b^2); ``G`` = X^T X (d, k, k) and ``c0`` = X^T e (d, k) per neuron."""
    k = G.shape[2]
    dinv = np.concatenate([np.full(k - 1, np.exp(-log_t[0])), [np.exp(-log_t[1])]])
    M = G / nu[:, None, None] + np.diag(dinv)
    c = c0 / nu[:, None]
    try:
        Lc = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return np.inf
    logdetM = 2.0 * np.sum(np.log(np.diagonal(Lc, axis1=1, axis2=2)), axis=1)
    y = np.linalg.solve(Lc, c[..., None])[..., 0]
    logdetD = -np.sum(np.log(dinv))
    return float(np.sum(logdetD + logdetM - np.einsum("dk,dk->d", y, y)))


def _mean_noise(data: _Data, act, th, s2):
    """Per neuron, the noise variance of a per-input mean: the pooled within-input variance over the
    shots of the residual at ``th`` (each shot against the model at its own regressor: with taps
    the regressor's own spread is part of the design, not of the noise), divided by r."""
    n, r, d = data.Y.shape
    if r < 2:
        return np.full(d, s2)
    if data.A.shape[1] == r:
        z = data.A @ th[:, :-1].T + th[:, -1]
        if data.hidden:
            vz = s2 * _unit_var(data, th[:, :-1])[:, None, :]
            z = act(z, np.broadcast_to(vz, z.shape))[0]
        E = data.Y - z
    else:
        E = data.Y
    return np.maximum(np.mean(np.var(E, axis=1, ddof=1), axis=0), 1e-12) / r


def _fit(data: _Data, act, W0, b0, s_guess: float, iters: int = 12):
    n, r, d = data.Y.shape
    th0 = np.concatenate([W0, b0[:, None]], axis=1)
    s2 = float(s_guess) ** 2
    s2 = _noise_level(data, act, th0, s2)
    Ybar = data.Y.mean(1)
    m, X, _ = _mean_model(data, act, th0, s2)
    nu = _mean_noise(data, act, th0, s2)
    e0 = Ybar - m
    scale_W = max(float(np.mean(W0 ** 2)), 1e-8)
    scale_b = max(float(np.mean(b0 ** 2)), 1e-2 * scale_W, 1e-8)
    start = np.log([0.01 * scale_W, 0.01 * scale_b])
    Xn = X.transpose(1, 0, 2)
    G, c0 = np.matmul(Xn.transpose(0, 2, 1), Xn), np.einsum("dnk,nd->dk", Xn, e0)
    res = optimize.minimize(_evidence, start, args=(G, c0, nu), method="Nelder-Mead",
                            options={"xatol": 1e-3, "fatol": 1e-3, "maxiter": 400})
    # the deviations a chip can have are at most of the programmed weights' size, a few times over
    cap = np.log(9.0 * np.array([scale_W, max(scale_b, scale_W)]) + 1e-2)
    log_t = np.clip(res.x, np.log(1e-12), cap)
    dinv = np.concatenate([np.full(W0.shape[1], np.exp(-log_t[0])), [np.exp(-log_t[1])]])

    def penalised(th):
        mm, XX, _ = _mean_model(data, act, th, s2)
        ee = Ybar - mm
        return np.sum(ee * ee, 0) / nu + np.sum((th - th0) ** 2 * dinv, 1), ee, XX

    th = th0.copy()
    obj, e, X = penalised(th)
    for _ in range(iters):
        Xn = X.transpose(1, 0, 2)
        M = np.matmul(Xn.transpose(0, 2, 1), Xn) / nu[:, None, None] + np.diag(dinv)
        grad = np.einsum("dnk,nd->dk", Xn, e) / nu[:, None] - (th - th0) * dinv
        step = np.linalg.solve(M, grad[..., None])[..., 0]
        # halve a neuron's step until its penalised loss does not rise (saturated neurons)
        for _ in range(6):
            new_obj, new_e, new_X = penalised(th + step)
            ok = new_obj <= obj + 1e-12 * np.abs(obj)
            if np.all(ok):
                break
            step = np.where(ok[:, None], step, 0.5 * step)
        ok = new_obj <= obj + 1e-12 * np.abs(obj)
        th = np.where(ok[:, None], th + step, th)
        obj = np.where(ok, new_obj, obj)
        _, e, X = penalised(th)
        if np.max(np.abs(step)) < 1e-8 * (1 + np.max(np.abs(th))):
            break
    s2 = _noise_level(data, act, th, s2)
    nu = _mean_noise(data, act, th, s2)
    Xn = X.transpose(1, 0, 2)
    M = np.matmul(Xn.transpose(0, 2, 1), Xn) / nu[:, None, None] + np.diag(dinv)
    cov = np.linalg.inv(M)
    se = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
    return th, se, float(np.sqrt(s2)), float(np.exp(0.5 * log_t[0])), float(np.exp(0.5 * log_t[1]))


def _propagated(meas: Measurement, s: float, draws: int = 256, seed: int = 0):
    """The model's mean (n, p) and unit covariance per s^2 (n, p, p) of a_{L-1} under the programmed
    hidden layers and additive noise s (Monte Carlo through the model, fixed draws)."""
    import jax

    from .._arch import Architecture
    from .._model import simulate
    from .._params import params32
    from ..effects import awgn

    hidden = meas.params[:-1]
    widths = (meas.arch.widths[0],) + tuple(int(W.shape[0]) for W, _ in hidden) + (int(hidden[-1][0].shape[0]),)
    # a network ending at layer L-1: an identity "output" layer over the last hidden one
    eye = np.eye(widths[-2])
    arch = Architecture(widths[:-1] + (widths[-2],), meas.activation)
    params = params32(tuple(hidden) + ((eye, np.zeros(widths[-2])),))
    out = simulate(jax.random.PRNGKey(seed), params, np.asarray(meas.x, np.float32), awgn(max(s, 1e-6)), arch, draws,
                   taps=True)
    a = np.asarray(out.taps[-2], np.float64)                       # (n, M, p): a_{L-1}
    mu = a.mean(1)
    dev = a - mu[:, None, :]
    cov = np.einsum("nki,nkj->nij", dev, dev) / ((draws - 1) * max(s, 1e-6) ** 2)
    return mu, cov


def fit_layers(meas: Measurement, *, s: float | None = None) -> tuple[LayerMap, ...]:
    """Every layer's realised map (taps) or the output layer's (no taps), see the module docstring.

    Parameters
    ----------
    meas : Measurement of the programmed weights ``meas.params``
    s : the noise level the fit starts from (default: read off the first measured layer's spread)

    Returns
    -------
    tuple of :class:`LayerMap`, in layer order (one entry, the output layer, without taps)
    """
    act = _activation(meas.activation)
    L = len(meas.params)
    x = np.asarray(meas.x, np.float64)
    p = x.shape[1]
    if s is None:
        Y0 = np.asarray(meas.layers()[0], np.float64)
        s = float(np.sqrt(np.mean(np.var(Y0, axis=1, ddof=1)) / 2.0)) if meas.r > 1 else 0.05
        s = max(s, 1e-6)
    out = []
    if meas.has_taps or L == 1:
        for l in range(1, L + 1):
            W, b = (np.asarray(v, np.float64) for v in meas.params[l - 1])
            Y = np.asarray(meas.layers()[l - 1], np.float64)
            if l == 1:
                data = _Data(x[:, None, :], Y, np.eye(p), L > 1)
            else:
                data = _Data(np.asarray(meas.taps[l - 2], np.float64), Y, None, l < L)
            th, se, s_l, tW, tb = _fit(data, act, W, b, s)
            out.append(LayerMap(l, th[:, :-1], th[:, -1], se[:, :-1], se[:, -1], W, b, s_l, tW, tb, meas.n, meas.r,
                                data.A, data.hidden))
        return tuple(out)
    W, b = (np.asarray(v, np.float64) for v in meas.params[-1])
    Y = np.asarray(meas.y, np.float64)
    for _ in range(3):  # the propagation at the level the output reads (two passes reach it)
        mu, C = _propagated(meas, s)
        th, se, s_new, tW, tb = _fit(_Data(mu[:, None, :], Y, C, False), act, W, b, s)
        if abs(s_new / s - 1.0) < 0.02:
            s = s_new
            break
        s = s_new
    return (LayerMap(L, th[:, :-1], th[:, -1], se[:, :-1], se[:, -1], W, b, s, tW, tb, meas.n, meas.r,
                     mu[:, None, :], False),)
