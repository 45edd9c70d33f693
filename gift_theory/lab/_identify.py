"""Layer-wise system identification: each layer's effective transfer and noise, read off the shots.

With taps, layer l's measured output is regressed on the measured output of layer l-1 of the
*same shot* (layer 1: on x). Under CONTRACTS §2 a tap is the value fed forward, so the
regressor of a shot is exactly the input its layer saw: the conditional mean of a_l given
a_{l-1} is the layer's mean map, with no error in the regressor (the noise of a_{l-1} is
part of the input, not an error of measuring it). Layer 1's input a_0 = x + n_a0 is not
measured: its noise enters the pre-activation as W n_a0 and is part of the model's noise.

Per layer (float64 numpy, closed form or a few Gauss-Newton steps, all neurons at once):

* **the mean map** ``W_eff, b_eff``: per neuron, least squares of the per-input mean output
  on the per-input mean of the linearised design ``sigma~'(z) [a, 1]`` (sigma~: the
  activation smoothed by the pre-activation's own noise, exact by Gauss-Hermite), iterated to
  the fixed point (Gauss-Newton). Its covariance is a sandwich whose meat is each input's
  within-cell covariance of the residuals across the layer's neurons (inputs are independent,
  neurons of one input are not), so every test below on it needs no assumed noise law;
* **restricted maps** on ``(W_eff - W, b_eff - b)`` by generalised least squares under that
  covariance: a gain (``W_eff = g W``), per-neuron bias shifts, a transfer of z (``g (W, b) + c``)
  and their combinations, and each neuron's own gain and shift of z (a detector's or
  modulator's gain and offset); the smallest one the data do not reject names the deviation;
* **dead or stuck neurons**: a row of W_eff indistinguishable from 0 where the programmed
  row is rejected;
* **the activation's shape**: binned means of the residual against the fitted z, shared by the
  layer's neurons, beyond each neuron's affine map (a function of z alone);
* **the noise**: its level per layer, its law (kurtosis of the standardised shots at equal
  variance), its dependence on the neuron's own signal and on the input's energy
  ``|a_{l-1}|^2``, the excess covariance across the layer's neurons within a shot (along the
  signal: a fluctuating gain; along the all-ones direction or anywhere else: correlated
  noise), and trends over acquisition time t (additive per neuron, a gain, a noise level).

Without taps the same is done at the output, its regressor the model's mean of a_{L-1} and
the noise of the hidden layers propagated to the output (linearised): a deviation there is
what every layer's deviation adds up to, and docs/identification.md lists what cannot be
separated.

Every test returns a p-value (:func:`tests`: Holm-adjusted over classes x layers), an
effect size and its layer; :mod:`._mechanisms` turns them into the ``mechanisms`` list.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from .._measurement import Measurement
from ._qtest import over_inputs

#: the level at which a restricted map is rejected (model choice) and a test counts
ALPHA = 0.01
#: bins of z of the activation's shape
BINS = 8
#: Gauss-Hermite nodes of the smoothed activation
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(6)
_GH_W = _GH_W / _GH_W.sum()
#: noise levels of two layers closer than this in log s^2 (5 %: 2.5 % in s) are one level
LEVEL_TOLERANCE = 0.05
#: layers whose stacked parameters exceed this are treated neuron by neuron (block-diagonal)
FULL_COV_MAX = 1600

#: each activation and its derivative, the derivative given the point z and the value f(z)
#: (tanh and the sigmoid reuse the value: the smoothing evaluates them at n r d 6 points)
_ACT = {
    "tanh": (np.tanh, lambda z, f: 1.0 - f * f),
    "identity": (lambda z: z, lambda z, f: np.ones_like(z)),
    "sigmoid": (lambda z: 1.0 / (1.0 + np.exp(-z)), lambda z, f: f * (1.0 - f)),
    "sin": (np.sin, lambda z, f: np.cos(z)),
}


def smoothed(activation: str, z, v, var: bool = True):
    """E sigma(z + sqrt(v) xi), its derivative in z and (``var``) Var sigma(z + sqrt(v) xi),
    xi ~ N(0, 1), by 6-point Gauss-Hermite (exact for polynomials of degree 11: for a smooth
    activation at a chip's noise levels, v << 1, the error is far below a shot's noise)."""
    f, df = _ACT[activation]
    sd = np.sqrt(np.maximum(v, 0.0))[..., None]
    pts = z[..., None] + sd * _GH_X
    F = f(pts)
    m = F @ _GH_W
    return m, df(pts, F) @ _GH_W, (np.maximum((F * F) @ _GH_W - m * m, 0.0) if var else None)


def _z_of_p(p):
    return float(stats.norm.isf(np.clip(p, 1e-300, 1.0)))


def _chi2(q, df, nu=None):
    """(p, z) of a chi-square statistic; z unbounded (Wilson-Hilferty past float range).

    ``nu``: the degrees of freedom of the covariance the quadratic form was built with (a Wald
    statistic under an estimated covariance is Hotelling's T^2: referred to F(df, nu - df + 1)
    scaled by nu df / (nu - df + 1), not to a chi-square that would call its noise a signal)."""
    df = max(int(df), 1)
    if nu is not None and np.isfinite(nu):
        nu = max(float(nu), df + 10.0)
        p = float(stats.f.sf(q * (nu - df + 1) / (nu * df), df, nu - df + 1))
        if p > 1e-250:
            return p, _z_of_p(p)
        q = q * (nu - df + 1) / nu  # past float range, the scaled statistic on the chi-square's z
    else:
        p = float(stats.chi2.sf(q, df))
    if p > 1e-250:
        return p, _z_of_p(p)
    return p, float(((q / df) ** (1 / 3) - (1 - 2 / (9 * df))) / np.sqrt(2 / (9 * df)))


def _two_sided(z):
    return float(min(1.0, 2.0 * stats.norm.sf(abs(z))))


# ---- the layers' inputs and the model's noise ------------------------------------------------

@dataclasses.dataclass
class _Layer:
    """What the identification of one layer reads.

    A : (n, r, p) or (n, 1, p) the regressor of each shot (the input the layer saw)
    Y : (n, r, d) the layer's measured shots
    Cin : (n, p, p) or None the unit covariance (per s^2) of the unmeasured part of the input
    W, b : programmed weights
    hidden : whether the activation follows
    """

    layer: int
    A: np.ndarray
    Y: np.ndarray
    Cin: np.ndarray | None
    W: np.ndarray
    b: np.ndarray
    hidden: bool


def _propagate(meas: Measurement, s: float):
    """Per input, the model's mean (n, d_l) and unit covariance (n, d_l, d_l) of every layer's
    output without taps: means through the smoothed activation, covariances linearised."""
    act = meas.activation
    m = np.asarray(meas.x, np.float64)
    n, p = m.shape
    C = np.broadcast_to(np.eye(p), (n, p, p)).copy()
    out = []
    L = len(meas.params)
    for l, (W, b) in enumerate(meas.params, start=1):
        W, b = np.asarray(W, np.float64), np.asarray(b, np.float64)
        Cz = np.matmul(np.matmul(W, C), W.T) + np.eye(W.shape[0])
        z = m @ W.T + b
        if l < L:
            vz = s * s * np.einsum("nii->ni", Cz)
            mu, slope, _ = smoothed(act, z, vz)
            C = slope[:, :, None] * Cz * slope[:, None, :] + np.eye(W.shape[0])
            m = mu
        out.append((m if l < L else z, C if l < L else Cz))
    return out


def _layers(meas: Measurement, s: float) -> list:
    L = len(meas.params)
    taps = meas.has_taps
    out = []
    x = np.asarray(meas.x, np.float64)
    n, p = x.shape
    if taps:
        for l in range(1, L + 1):
            W, b = (np.asarray(v, np.float64) for v in meas.params[l - 1])
            Y = np.asarray(meas.layers()[l - 1], np.float64)
            if l == 1:
                out.append(_Layer(1, x[:, None, :], Y, np.broadcast_to(np.eye(p), (n, p, p)), W, b, L > 1))
            else:
                out.append(_Layer(l, np.asarray(meas.taps[l - 2], np.float64), Y, None, W, b, l < L))
        return out
    W, b = (np.asarray(v, np.float64) for v in meas.params[-1])
    if L == 1:
        return [_Layer(1, x[:, None, :], np.asarray(meas.y, np.float64), np.broadcast_to(np.eye(p), (n, p, p)), W, b,
                       False)]
    m, C = _propagate(meas, s)[L - 2]
    return [_Layer(L, m[:, None, :], np.asarray(meas.y, np.float64), C, W, b, False)]


def _unit_cov(lay: _Layer, W_eff):
    """The unit (per s^2) covariance of the pre-activation noise of each input (n, d, d)."""
    d = W_eff.shape[0]
    n = lay.Y.shape[0]
    if lay.Cin is None:
        return np.broadcast_to(np.eye(d), (n, d, d))
    return np.matmul(np.matmul(W_eff, lay.Cin), W_eff.T) + np.eye(d)


def _unit_var(lay: _Layer, W_eff):
    """The diagonal of :func:`_unit_cov` (n, d): what the means need."""
    n, d = lay.Y.shape[0], W_eff.shape[0]
    if lay.Cin is None:
        return np.ones((n, d))
    return np.sum(np.matmul(W_eff, lay.Cin) * W_eff, axis=-1) + 1.0


def _mean_model(lay: _Layer, act: str, W_eff, b_eff, s2, vu, tt=None, drift=None, want_var=True):
    """Per shot: the pre-activation, the model's mean, slope d mean / dz and the layer's own
    noise variance (n, r, d) at the map (W_eff, b_eff), noise level s^2 (``vu``: the unit
    variance of the pre-activation noise, (n, d), :func:`_unit_var`) and, with acquisition
    times (``tt``: t, (n, r)), the trends ``drift`` = (c, k) (d,) each: an additive
    trend c t and a gain trend k t W a of the pre-activation (the map itself is at t = 0)."""
    z = lay.A @ W_eff.T + b_eff
    if tt is not None and drift is not None:
        z = z + tt[:, :, None] * (drift[0] + drift[1] * (lay.A @ lay.W.T))
    vz = s2 * vu[:, None, :]
    if lay.hidden:
        m, g, var = smoothed(act, z, np.broadcast_to(vz, z.shape), var=want_var)
        return z, m, g, (var + s2 if want_var else None)
    return z, z, np.ones_like(z), np.broadcast_to(vz, z.shape)


def _cell_cov(E):
    """Per input, the covariance across shots of the residuals (n, d, d) (ddof 1)."""
    r = E.shape[1]
    c = E - E.mean(1, keepdims=True)
    return np.einsum("nki,nkj->nij", c, c) / max(r - 1, 1)


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
        Xt = X.transpose(1, 0, 2)  # (d, n, k)
        B = np.matmul(Xt.transpose(0, 2, 1), Xt)
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
    Czu = _unit_cov(lay, W)
    z, m, g, var = _mean_model(lay, act, W, b, s2, np.einsum("nii->ni", Czu), tt, drift)
    X = _design(lay, g, tt)
    E = lay.Y - m  # (n, r, d) residual per shot (each shot against the mean at its own regressor)
    return W, b, drift, z, m, g, var, X, E, Czu


def _within(E, g, A):
    """The residuals with their within-input part along the layer's own input removed.

    With taps a layer's regressor varies from shot to shot (its input's noise), and W_eff --
    read off the per-input means -- carries an error that moves the residuals within an input
    along g (a - mean a): the within-input variance would hold that error too (measured: +3 %
    at 60 inputs x 16 shots on a hidden layer of 12 inputs). Per neuron, the within-input
    deviations are regressed on g (a - mean a) (pooled over inputs) and the fit removed; the
    caller divides by the degrees of freedom left. Layer 1 (one regressor per input): unchanged."""
    if A.shape[1] == 1:
        return E
    n, r, d = E.shape
    p = A.shape[2]
    Ed = E - E.mean(1, keepdims=True)
    out = np.array(E, dtype=np.float64, copy=True)
    # neuron by neuron: the (n r, p) design of one neuron at a time (all at once it is d n r p
    # floats: 1.3 GB on a 100-neuron layer fed by 500 at 200 inputs x 16 shots)
    for i in range(d):
        Gi = g[:, :, i, None] * A  # (n, r, p)
        Gi = (Gi - Gi.mean(1, keepdims=True)).reshape(n * r, p)
        beta = np.linalg.solve(Gi.T @ Gi + 1e-12 * np.eye(p), Gi.T @ Ed[:, :, i].reshape(n * r))
        out[:, :, i] -= (Gi @ beta).reshape(n, r)
    return out


def _covariance(X, Chat, r):
    """The sandwich covariance of the stacked per-neuron least squares (d (p+1) square), or
    its per-neuron blocks (d, p+1, p+1) when the layer is wide."""
    n, d, k = X.shape
    B = np.einsum("nip,niq->ipq", X, X) + 1e-12 * np.eye(k)
    Binv = np.linalg.inv(B)
    if d * k <= FULL_COV_MAX:
        meat = np.einsum("nij,nip,njq->ipjq", Chat / r, X, X, optimize=True)
        S = np.einsum("iab,ibjc,jdc->iajd", Binv, meat, Binv, optimize=True)
        return S.reshape(d * k, d * k), True
    meat = np.einsum("ni,nip,niq->ipq", np.einsum("nii->ni", Chat) / r, X, X)
    return np.einsum("iab,ibc,idc->iad", Binv, meat, Binv), False


def _solve_psd(S, v):
    try:
        return np.linalg.solve(S, v)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(S) @ v


def _gls(theta, S, R):
    """GLS of theta ~ N(R phi, S): phi, its covariance and the misfit chi-square."""
    Si_R = _solve_psd(S, R)
    F = R.T @ Si_R
    Fi = np.linalg.pinv(F)
    phi = Fi @ (Si_R.T @ theta)
    q_full = float(theta @ _solve_psd(S, theta))
    return phi, Fi, max(q_full - float(phi @ F @ phi), 0.0)


# ---- per-layer identification ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class LayerIdentity:
    """One layer, identified from the shots.

    layer : 1-based
    W_eff, b_eff : (d, p), (d,) the effective mean map
    theta_se : (d, p+1) standard errors of its entries
    gain, gain_se : the best common gain g (W_eff ~ g W, biases free) and its standard error
    dead : neurons (0-based) whose effective row is 0 while the programmed one is not
    choice : the smallest restricted map the data do not reject: "programmed", "gain",
        "transfer", "bias", "gain+bias", "rows" (per-neuron gain and shift of z) or "general"
    z_bins : (B,) centres of the bins of z; shape : (B,) the binned mean residual shared by the
        neurons beyond their affine maps (the activation's shape deviation); curve : (d, B) per
        neuron the binned mean residual against the programmed z (a flat neuron is dead)
    s : the layer's own noise level; s_se its standard error
    kurtosis : mean excess kurtosis of the standardised shots (0 for a Gaussian law)
    rows : the tests ({class, test, p, z, effect, evidence, neurons})
    """

    layer: int
    W_eff: np.ndarray
    b_eff: np.ndarray
    theta_se: np.ndarray
    gain: float
    gain_se: float
    dead: tuple
    choice: str
    z_bins: np.ndarray
    shape: np.ndarray
    curve: np.ndarray
    s: float
    s_se: float
    kurtosis: float
    rows: tuple


def _row(cls, test, p, z, effect, evidence, neurons=()):
    return {"class": cls, "test": test, "p": float(min(max(p, 0.0), 1.0)), "z": float(z), "effect": float(effect),
            "evidence": evidence, "neurons": tuple(int(i) for i in neurons)}


def _identify_layer(lay: _Layer, act: str, s_guess: float, t, depth: int, taps: bool) -> LayerIdentity:
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    l = lay.layer
    transfer_cls = "activation_mismatch" if lay.hidden else "readout_nonlinearity"
    tt = None
    if t is not None:
        # the map is identified at t = 0, the start of the acquisition (CONTRACTS §2's drift is
        # g = 1 + r t): a trend's time average is not a fixed error
        # the map's trends come from the inputs' mean times (a within-input trend would make the
        # model's mean move inside an input by a coefficient read off the means); they are fitted
        # only where those spread over a tenth of the campaign (not with an interleaved order,
        # where the within-input test below sees the trend)
        t = np.asarray(t, np.float64)
        tbar = t.mean(1, keepdims=True)
        tt = tbar if np.std(tbar) >= 0.1 else None
    k = p + 1 + (2 if tt is not None else 0)
    # noise level: two passes (the smoothing of sigma depends on it, only at second order)
    s2 = s_guess ** 2
    W0 = b0 = None
    for _ in range(2):
        W_eff, b_eff, drift, z, m, g, var, X, E, Czu = _fit_map(lay, act, s2, tt, W0=W0, b0=b0)
        W0, b0 = W_eff, b_eff
        Chat = _cell_cov(_within(E, g, lay.A))
        if lay.A.shape[1] > 1:
            Chat = Chat * n * (r - 1) / max(n * (r - 1) - p, 1)
        s2 = float(np.sum(np.einsum("nii->ni", Chat)) / np.sum((var / s2).mean(1)))
    W_eff, b_eff, drift, z, m, g, var, X, E, Czu = _fit_map(lay, act, s2, tt, W0=W0, b0=b0)
    E = _within(E, g, lay.A)
    Chat = _cell_cov(E)
    if lay.A.shape[1] > 1:  # the within-cell regression spent p degrees of freedom per neuron
        f = np.sqrt(n * (r - 1) / max(n * (r - 1) - p, 1))
        Chat = Chat * f * f
    vu = var / s2
    rows = []

    # ---- the mean map and its restrictions
    S, full = _covariance(X, Chat, r)
    # the covariance's own degrees of freedom: r - 1 per input, inputs weighted by their leverage
    lev = np.einsum("nip->n", X ** 2)
    nu = float(lev.sum() ** 2 / max(np.sum(lev ** 2), 1e-300)) * max(r - 1, 1)
    dW, db = W_eff - lay.W, b_eff - lay.b
    parts = [dW, db[:, None]] + ([drift[0][:, None], drift[1][:, None]] if tt is not None else [])
    theta = np.concatenate(parts, axis=1)  # (d, k)
    se = (np.sqrt(np.maximum(np.diag(S), 1e-300)).reshape(d, k) if full
          else np.sqrt(np.maximum(np.einsum("ipp->ip", S), 1e-300)))
    # dead or stuck neurons: W_eff row compatible with 0, the programmed row rejected
    dead, dead_p = [], []
    for i in range(d):
        Si = S[i * k:i * k + p, i * k:i * k + p] if full else S[i, :p, :p]
        q0 = float(W_eff[i] @ _solve_psd(Si, W_eff[i]))
        q1 = float(dW[i] @ _solve_psd(Si, dW[i]))
        p0, p1 = _chi2(q0, p, nu)[0], _chi2(q1, p, nu)[0]
        if p0 >= ALPHA and p1 * d < ALPHA and np.linalg.norm(lay.W[i]) > 0:
            dead.append(i)
            dead_p.append(min(1.0, p1 * d))
    if dead:
        j = int(np.argmin(dead_p))
        q1 = float(dW[dead[j]] @ _solve_psd(S[dead[j] * k:dead[j] * k + p, dead[j] * k:dead[j] * k + p] if full
                                             else S[dead[j], :p, :p], dW[dead[j]]))
        rows.append(_row(transfer_cls, "dead", min(dead_p), _chi2(q1, p, nu)[1], len(dead),
                         f"neuron(s) {', '.join(f'{l}:{i}' for i in dead)} respond to nothing: effective row 0 "
                         f"(the programmed row rejected, p = {dead_p[j]:.2g}); a dead or stuck neuron", dead))
    alive = [i for i in range(d) if i not in dead]
    da = len(alive)
    idx = np.concatenate([np.arange(i * k, (i + 1) * k) for i in alive]) if alive else np.zeros(0, int)
    th = theta[alive].ravel()
    if full:
        Sa = S[np.ix_(idx, idx)]
    else:
        Sa = np.zeros((len(idx), len(idx)))
        for a_, i in enumerate(alive):
            Sa[a_ * k:(a_ + 1) * k, a_ * k:(a_ + 1) * k] = S[i]
    Wa, ba = lay.W[alive], lay.b[alive]

    def unit(pos):  # per alive neuron, the column moving entry ``pos`` of its theta
        R = np.zeros((da * k, da))
        R[np.arange(da) * k + pos, np.arange(da)] = 1.0
        return R

    # designs of the restricted maps (columns: how theta moves with each parameter); the time
    # trends, when there are times, are free in every map
    free = np.concatenate([unit(p + 1), unit(p + 2)], axis=1) if tt is not None else np.zeros((da * k, 0))
    pad = np.zeros((da, k - p - 1))
    Rg = np.concatenate([Wa, np.zeros((da, 1)), pad], axis=1).reshape(-1, 1)
    Rb = unit(p)
    Rt = np.stack([np.concatenate([Wa, ba[:, None], pad], axis=1).ravel(), Rb.sum(1)], axis=1)
    Rr = np.zeros((da * k, da))  # per-neuron gain on the whole pre-activation (W and b of that row)
    for a_ in range(da):
        Rr[a_ * k:a_ * k + p + 1, a_] = np.concatenate([Wa[a_], [ba[a_]]])
    models = {"programmed": free, "gain": np.concatenate([Rg, free], 1), "transfer": np.concatenate([Rt, free], 1),
              "bias": np.concatenate([Rb, free], 1), "gain+bias": np.concatenate([Rg, Rb, free], 1),
              "rows": np.concatenate([Rr, Rb, free], 1)}
    gain, gain_se = 1.0, float("inf")
    choice = "general"
    rel = 0.0
    W_idx = (np.arange(da)[:, None] * k + np.arange(p)[None, :]).ravel()
    if da:
        fits = {name: _gls(th, Sa, R) for name, R in models.items()}
        pfit = {name: _chi2(f[2], th.size - models[name].shape[1], nu)[0] for name, f in fits.items()}
        q0 = fits["programmed"][2]
        p_omni, z_omni = _chi2(q0, th.size - free.shape[1], nu)
        # where both fit (biases near 0: a gain on W is a gain on z), a hidden layer's is read as
        # its activation's slope, the output's as a gain on its weighted sum
        order = (("programmed", "transfer", "gain") if lay.hidden else ("programmed", "gain", "transfer")) \
            + ("bias", "gain+bias", "rows")
        for name in order:
            if pfit[name] >= ALPHA:
                choice = name
                break
        phi, Fi, _ = fits["gain+bias"]
        gain, gain_se = 1.0 + float(phi[0]), float(np.sqrt(max(Fi[0, 0], 0.0)))
        # a weight error E drawn apart from W moves the gain estimate: its scatter (tau^2 per entry,
        # the excess of E beyond the gain over its noise) is part of the gain's error
        # beyond a gain, the gain is read off by projection on W (unweighted: weights that depend on
        # the data would correlate with a weight error E), its error the noise's plus E's scatter
        # tau^2 per entry (the excess of E beyond the gain over its noise): <E, W> / |W|^2
        w2 = float(np.sum(Wa ** 2))
        g_ols = 1.0 + float(np.sum(dW[alive] * Wa)) / max(w2, 1e-300)
        Eg = dW[alive] - (g_ols - 1.0) * Wa
        tau2 = max(0.0, float(np.mean(Eg ** 2) - np.mean(se[alive, :p] ** 2)))
        wv = Wa.ravel()
        g_se_tot = float(np.sqrt(max(wv @ Sa[np.ix_(W_idx, W_idx)] @ wv, 0.0) / max(w2, 1e-300) ** 2
                                 + tau2 / max(w2, 1e-300)))
        rel = float(np.sqrt(np.mean(Eg ** 2)) / max(np.sqrt(np.mean(Wa ** 2)), 1e-300))
        if choice in ("gain+bias", "general"):
            gain = g_ols
        g_at = gain
        trend = ""
        se_use = gain_se if choice == "gain" else g_se_tot
        z_gain = (g_at - 1.0) / se_use if se_use > 0 else 0.0

        def floor(pv):  # no class is more significant than the omnibus deviation from the programmed map
            return max(pv, p_omni)

        if choice == "gain":
            rows.append(_row("gain_error", "gain", floor(_two_sided(z_gain)), abs(z_gain), g_at - 1.0,
                             f"W_eff = {gain:.3f} W at layer {l} (+- {gain_se:.2g}{trend}); nothing else of the map "
                             f"differs (p = {pfit['gain']:.2g})"))
        elif choice == "transfer":
            phi_t, Fi_t, _ = fits["transfer"]
            qt = float(phi_t[:2] @ np.linalg.solve(Fi_t[:2, :2], phi_t[:2]))
            pt, zt = _chi2(qt, 2, nu)
            rows.append(_row(transfer_cls, "transfer", floor(pt), zt, phi_t[0],
                             f"z scaled as a whole at layer {l}: {1 + phi_t[0]:.3f} (W, b) + {phi_t[1]:.3g} "
                             f"(a {'slope/shift of the activation' if lay.hidden else 'gain/offset of the readout'}; "
                             f"fits, p = {pfit['transfer']:.2g})"))
        elif choice == "rows":
            phi_r, Fi_r, _ = fits["rows"]
            qr = float(phi_r[:2 * da] @ _solve_psd(Fi_r[:2 * da, :2 * da], phi_r[:2 * da]))
            pr, zr = _chi2(qr, 2 * da, nu)
            gi = phi_r[:da]
            rows.append(_row(transfer_cls, "neuron_transfer", floor(pr), zr, float(np.sqrt(np.mean(gi ** 2))),
                             f"each neuron's z at layer {l} scaled and shifted on its own: gains "
                             f"{1 + gi.min():.3f}..{1 + gi.max():.3f} on (W, b) of its row, shifts rms "
                             f"{np.sqrt(np.mean(phi_r[da:2 * da] ** 2)):.3g} (a "
                             f"{'modulator' if lay.hidden else 'detector'}'s gain and offset; fits, p = {pfit['rows']:.2g})"))
        elif choice in ("bias", "gain+bias", "general"):
            if choice in ("gain+bias", "general"):
                rows.append(_row("gain_error", "gain", floor(_two_sided(z_gain)), abs(z_gain), g_at - 1.0,
                                 f"common gain {gain:.3f} on W at layer {l} (+- {g_se_tot:.2g} with the rest of "
                                 f"the map's error{trend})"))
            if choice == "general":
                q_w = fits["gain+bias"][2]
                df_w = th.size - models["gain+bias"].shape[1]
                pw, zw = _chi2(q_w, df_w, nu)
                rows.append(_row("weight_error", "map", floor(pw), zw, rel,
                                 f"W_eff - W beyond a gain and bias shifts at layer {l}: rms {rel:.2g} of rms W "
                                 f"(chi2 {q_w:.0f} on {df_w} df)"))
            # bias shifts: in the least restrictive map not rejected (general: W free)
            b_idx = np.arange(da) * k + p
            if choice == "general":
                dbs, Sb = th[b_idx], Sa[np.ix_(b_idx, b_idx)]
            else:
                phi_b, Fi_b, _ = fits[choice]
                o = 1 if choice == "gain+bias" else 0
                dbs, Sb = phi_b[o:o + da], Fi_b[o:o + da, o:o + da]
            qb = float(dbs @ _solve_psd(Sb, dbs))
            pb, zb = _chi2(qb, da, nu)
            zs = dbs / np.sqrt(np.maximum(np.diag(Sb), 1e-300))
            worst = int(np.argmax(np.abs(zs)))
            rows.append(_row("bias_offset", "bias", floor(pb), zb, float(np.sqrt(np.mean(dbs ** 2))),
                             f"per-neuron shifts of z at layer {l}: rms {np.sqrt(np.mean(dbs ** 2)):.3g}, "
                             f"largest {dbs[worst]:+.3g} at {l}:{alive[worst]} (z = {zs[worst]:.1f})",
                             [alive[worst]]))
        rows.append(_row("weight_error" if choice == "programmed" else "_omnibus", "omnibus",
                         p_omni if choice == "programmed" else 1.0, z_omni if choice == "programmed" else 0.0, rel,
                         f"the map at layer {l} is the programmed one (p = {p_omni:.2g})"))
        if tt is not None:
            tr = np.concatenate([np.arange(da) * k + p + 1, np.arange(da) * k + p + 2])
            qt = float(th[tr] @ _solve_psd(Sa[np.ix_(tr, tr)], th[tr]))
            pt, zt = _chi2(qt, tr.size, nu)
            zc_ = th[tr] / np.sqrt(np.maximum(np.diag(Sa)[tr], 1e-300))
            wi = int(np.argmax(np.abs(zc_)))
            rows.append(_row("time_drift", "time_map", pt, zt, float(np.max(np.abs(th[tr]))),
                             f"the map at layer {l} moves over acquisition time: "
                             f"{'additive' if wi < da else 'gain'} trend {th[tr][wi]:+.3g} per unit t at "
                             f"{l}:{alive[wi % da]} (z = {zc_[wi]:.1f}; chi2 z = {zt:.1f} over the layer)",
                             [alive[wi % da]]))

    # ---- the activation's shape: binned residual shared by the neurons, beyond each affine map
    ebar = E.mean(1)
    zz = z[:, :, alive] if alive else z
    edges = np.quantile(zz, np.linspace(0, 1, BINS + 1))
    edges[0], edges[-1] = -np.inf, np.inf
    idxb = np.clip(np.searchsorted(edges, z, side="right") - 1, 0, BINS - 1)
    H = np.stack([(idxb == j).mean(1) for j in range(BINS)], axis=-1)  # (n, d, B)
    Bx = np.linalg.inv(np.einsum("nip,niq->ipq", X, X) + 1e-12 * np.eye(k))
    proj = np.einsum("nip,ipq,iqb->nib", X, Bx, np.einsum("miq,mib->iqb", X, H))
    Ht = (H - proj)[:, alive]
    ea = ebar[:, alive]
    Ca = Chat[:, alive][:, :, alive]
    Sg = np.einsum("nib,ni->b", Ht, ea)
    Vg = np.einsum("nij,nib,njc->bc", Ca / r, Ht, Ht, optimize=True)
    w_, U_ = np.linalg.eigh(Vg)
    keep = w_ > 1e-9 * max(w_.max(), 1e-300)
    qs = float(np.sum((U_[:, keep].T @ Sg) ** 2 / w_[keep]))
    ps, zs_ = _chi2(qs, int(keep.sum()), nu)
    gam = np.linalg.pinv(np.einsum("nib,nic->bc", Ht, Ht)) @ Sg
    inner = edges[1:-1]
    zc = np.concatenate([[inner[0] - 0.5 * (inner[1] - inner[0])], 0.5 * (inner[:-1] + inner[1:]),
                         [inner[-1] + 0.5 * (inner[-1] - inner[-2])]])
    jmax = int(np.argmax(np.abs(gam)))
    rows.append(_row(transfer_cls, "shape", ps, zs_, float(np.max(np.abs(gam))),
                     f"the residual at layer {l} is a function of z shared by its neurons: {gam[jmax]:+.3g} "
                     f"near z = {zc[jmax]:.2g} beyond each neuron's affine map"))
    # per-neuron residual against the programmed z (the nonparametric curve, for the evidence)
    z0 = np.einsum("nkp,ip->nki", lay.A, lay.W) + lay.b
    res0 = lay.Y - _mean_model(lay, act, lay.W, lay.b, s2, _unit_var(lay, lay.W))[1]
    e0 = np.quantile(z0, np.linspace(0, 1, BINS + 1))
    e0[0], e0[-1] = -np.inf, np.inf
    i0 = np.clip(np.searchsorted(e0, z0, side="right") - 1, 0, BINS - 1)
    i0 = np.broadcast_to(i0, res0.shape)
    curve = np.stack([np.sum(np.where(i0 == j, res0, 0.0), axis=(0, 1)) / np.maximum(np.sum(i0 == j, axis=(0, 1)), 1)
                      for j in range(BINS)], axis=-1)

    # ---- the noise
    vcell = vu.mean(1)  # (n, d) unit variance of a cell
    obs = np.einsum("nii->ni", Chat)
    u = (z.mean(1) - b_eff)  # the weighted sum
    wg = (g.mean(1) * u) if lay.hidden else u  # how the layer's output moves with a gain on it
    # the level: observed over unit variances of the cells; its error over inputs
    Tl = np.sum(obs - s2 * vcell, axis=1)
    s_lvl = float(np.sqrt(s2))
    s_se = float(np.sqrt(n * np.var(Tl, ddof=1)) / max(np.sum(vcell), 1e-300) / (2 * s_lvl))
    dev = (E - E.mean(1, keepdims=True)) / np.sqrt(np.maximum(var, 1e-300))
    m2 = np.mean(dev ** 2, 1)
    kurt_cell = np.mean(dev ** 4, 1) / np.maximum(m2 * m2, 1e-300) - 3.0
    kurt0 = -6.0 / (r + 1)
    kz = over_inputs(kurt_cell.mean(1) - kurt0) if r >= 4 else 0.0
    kurt = float(np.mean(kurt_cell) - kurt0)
    rows.append(_row("noise_law", "kurtosis", _two_sided(kz), abs(kz), kurt,
                     f"excess kurtosis {kurt:+.2f} of the standardised shots at layer {l} (0 for a Gaussian law)"))
    # variance against the neuron's own signal and the input's energy
    rho = obs / np.maximum(s2 * vcell, 1e-300) - 1.0
    own = np.abs(z).mean(1)
    own = own - own.mean(0)
    energy = np.sum(lay.A ** 2, axis=2).mean(1)
    energy = energy - energy.mean()
    z_own = over_inputs(np.sum(rho * own, 1))
    z_en = over_inputs(rho.mean(1) * energy) if np.std(energy) > 0 else 0.0
    which = "the neuron's own |z|" if abs(z_own) >= abs(z_en) else "the input's energy |a_{l-1}|^2"
    zi = max(abs(z_own), abs(z_en))
    slope_own = float(np.sum(rho * own) / max(np.sum(own ** 2), 1e-300))
    rows.append(_row("input_dependent_noise", "variance", min(1.0, 2 * _two_sided(zi)), zi, slope_own,
                     f"the noise variance at layer {l} changes with {which} (z = {z_own:.1f} own signal, "
                     f"{z_en:.1f} input energy)"))
    # covariance across the layer's neurons within a shot, beyond the model's
    if d > 1:
        off = 1 - np.eye(d)
        # the model's off-diagonal pattern (layer 1, no taps: the unmeasured input noise through W),
        # its scale fitted (a level misjudged elsewhere must not look like a correlation)
        M = (g.mean(1)[:, :, None] * (Czu - np.eye(d)) * g.mean(1)[:, None, :]) if lay.hidden else (Czu - np.eye(d))
        M = np.broadcast_to(M, Chat.shape) * off
        mm = float(np.sum(M * M))
        Cm = (float(np.sum(Chat * M)) / mm) * M if mm > 0 else np.zeros_like(Chat)

        def along(w):
            w = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
            a = np.einsum("ni,nij,nj->n", w, (Chat - Cm) * off, w)
            b_ = np.einsum("ni,ni->n", w * w, obs)
            return over_inputs(a / np.maximum(b_, 1e-300)), w, a

        z_g, wn, a_g = along(wg)
        rows.append(_row("gain_fluctuation", "common_gain", stats.norm.sf(z_g), z_g, z_g,
                         f"excess covariance along the signal at layer {l} (z = {z_g:.1f}): a gain shared by the "
                         f"neurons, fluctuating from shot to shot"))
        z1 = along(np.ones((n, d)))[0]
        z_s = along(g.mean(1))[0] if lay.hidden else z1
        # any correlation beyond the signal's direction: the off-diagonal covariance, less a fitted
        # rank-one part along the signal, squared, beyond its null size
        alpha = a_g / np.maximum(1.0 - np.sum(wn ** 4, 1), 1e-300)
        dC = (Chat - Cm - alpha[:, None, None] * wn[:, :, None] * wn[:, None, :]) * off
        null = (obs[:, :, None] * obs[:, None, :] + Cm ** 2) / max(r - 1, 1) * off
        U = np.sum(dC ** 2 - null, axis=(1, 2)) / np.maximum(np.sum(null, axis=(1, 2)), 1e-300)
        z_u = over_inputs(U)
        zc_ = max(z1, z_s, z_u)
        what = ("along all neurons alike (common additive noise)" if zc_ == z1 else
                "along sigma'(z) (common noise before the activation)" if zc_ == z_s else
                "in a pattern beyond the signal's direction")
        rows.append(_row("correlated_noise", "correlation", min(1.0, 3 * stats.norm.sf(zc_)), zc_, zc_,
                         f"noise correlated across the neurons of layer {l} {what} (z = {z1:.1f} common, "
                         f"{z_u:.1f} any pattern)"))
    if t is not None and r > 2 and np.std(t - t.mean(1, keepdims=True)) > 0:
        # trends within an input's shots (acquisition order interleaved across inputs): the
        # within-input residuals against t - its input's mean, additive per neuron and a gain
        tw = t - t.mean(1, keepdims=True)
        Ed = E - E.mean(1, keepdims=True)
        gk = np.broadcast_to(g, E.shape)
        rows_t = []
        for name, D in (("additive", gk * tw[:, :, None]), ("gain", gk * np.broadcast_to(u[:, None, :], E.shape)
                                                              * tw[:, :, None])):
            S_ = np.sum(D * D, axis=(0, 1))
            beta = np.sum(D * Ed, axis=(0, 1)) / np.maximum(S_, 1e-300)
            M = np.einsum("nki,nkj->nij", D, D)
            Cb = np.einsum("nij,nij->ij", M, Chat) / np.maximum(np.outer(S_, S_), 1e-300)
            if name == "additive":
                q = float(beta @ _solve_psd(Cb, beta))
                rows_t.append((name, *_chi2(q, d), beta, Cb))
            else:  # one relative gain trend shared by the neurons: the precision-weighted mean
                wv = 1.0 / np.maximum(np.diag(Cb), 1e-300)
                wv = wv / wv.sum()
                kb = float(wv @ beta)
                zk = kb / np.sqrt(max(float(wv @ Cb @ wv), 1e-300))
                rows_t.append((name, _two_sided(zk), abs(zk), beta, Cb))
        best = min(rows_t, key=lambda x: x[1])
        zc_ = best[3] / np.sqrt(np.maximum(np.diag(best[4]), 1e-300))
        wi = int(np.argmax(np.abs(zc_)))
        rows.append(_row("time_drift", "time_within", min(1.0, 2 * best[1]), best[2], float(best[3][wi]),
                         f"within the inputs' shots, layer {l} moves with acquisition time: {best[0]} trend "
                         f"{best[3][wi]:+.3g} per unit t at {l}:{wi} (z = {zc_[wi]:.1f}; the layer's z = {best[2]:.1f})",
                         [wi]))
    if t is not None and np.std(t.mean(1)) > 0:
        tc = t.mean(1) - t.mean()
        z_vt = over_inputs(tc * rho.mean(1))
        rows.append(_row("time_drift", "time_noise", _two_sided(z_vt), abs(z_vt), z_vt,
                         f"the noise level at layer {l} moves over acquisition time (z = {z_vt:.1f})"))
    return LayerIdentity(l, W_eff, b_eff, se, gain, gain_se, tuple(dead), choice, zc, gam, curve,
                         s_lvl, s_se, kurt, tuple(rows))


@dataclasses.dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`LayerIdentity` per identified layer.

    taps : whether each layer was identified on its own (taps) or only the output
    levels_row : the test of equal noise levels across layers (taps), or None
    """

    taps: bool
    depth: int
    layers: tuple
    levels_row: dict | None = None

    def rows(self) -> list[dict]:
        """Every test with its layer and Holm-adjusted p-value (``p_adj``) over classes x layers."""
        out = []
        for li in self.layers:
            for rw in li.rows:
                if rw["class"] != "_omnibus":
                    out.append(dict(rw, layer=li.layer))
        if self.levels_row is not None:
            out.append(dict(self.levels_row))
        ps = np.array([r_["p"] for r_ in out])
        order = np.argsort(ps)
        m = len(ps)
        adj, run = np.empty(m), 0.0
        for rank, i in enumerate(order):
            run = max(run, min(1.0, (m - rank) * ps[i]))
            adj[i] = run
        for r_, a in zip(out, adj):
            r_["p_adj"] = float(a)
        return out

    def by_layer(self) -> dict:
        return {li.layer: li for li in self.layers}


def identify(meas: Measurement, s: float | None = None) -> Identification:
    """Identify every layer of ``meas`` (taps) or its output (no taps) from the shots.

    Parameters
    ----------
    meas : Measurement
    s : the noise level the identification starts from (the smoothing of the activation);
        default: read off the within-input spread of the first measured layer

    Returns
    -------
    Identification
    """
    # small dense algebra: one BLAS thread (threads spinning on a loaded machine cost 100x here)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn brings it
        import contextlib
        limits = contextlib.nullcontext()
    else:
        limits = threadpool_limits(1)
    with limits:
        return _identify(meas, s)


def _identify(meas: Measurement, s: float | None) -> Identification:
    act = meas.activation if meas.activation in _ACT else "tanh"
    if s is None:
        Y0 = np.asarray(meas.layers()[0], np.float64)
        s = float(np.sqrt(np.mean(np.var(Y0, axis=1, ddof=1)) / 2.0)) if meas.r > 1 else 0.05
        s = max(s, 1e-6)
    lays = _layers(meas, s)
    out = [_identify_layer(lay, act, s, meas.t, meas.arch.depth, meas.has_taps) for lay in lays]
    if not meas.has_taps and meas.arch.depth > 1:
        # the output's regressor and noise are propagated at the level s: once more at the level found
        s = out[-1].s
        out = [_identify_layer(lay, act, s, meas.t, meas.arch.depth, False) for lay in _layers(meas, s)]
    levels = None
    if meas.has_taps and len(out) > 1:
        x = np.array([np.log(li.s ** 2) for li in out])
        se = np.array([2 * li.s_se / max(li.s, 1e-300) for li in out])
        w = 1.0 / np.maximum(se ** 2, 1e-300)
        xb = float(np.sum(w * x) / np.sum(w))
        # levels within LEVEL_TOLERANCE of each other (in log s^2) are one level: the layers' unit
        # variances are modelled to about 1 % at 16 shots per input (measured on null files)
        q = float(np.sum(w * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) ** 2))
        p, z = _chi2(q, len(out) - 1)
        zl = np.sign(x - xb) * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) * np.sqrt(w)
        bad = [li.layer for li, zz in zip(out, zl) if abs(zz) > 3.0]
        worst = int(np.argmax(np.abs(zl)))
        levels = _row("noise_level", "levels", p, z, float(out[worst].s),
                      "noise levels per layer " + ", ".join(f"{li.s:.3g}" for li in out)
                      + f" (layer {out[worst].layer} stands out, z = {zl[worst]:.1f})")
        levels["layer"] = out[worst].layer
        levels["layers"] = bad or [out[worst].layer]
    return Identification(meas.has_taps, meas.arch.depth, tuple(out), levels)


#: what the output alone cannot separate (no taps); docs/identification.md has the full table
CANNOT_SEPARATE_WITHOUT_TAPS = (
    "which layer a deviation of the mean map, the gain or the biases sits in (all fold into the output's)",
    "an activation's shape from a readout's transfer",
    "the noise level of one layer from another's (one level is seen)",
)
