"""Layer-wise system identification: each layer's effective transfer and noise, read off the shots.

With taps, layer l's measured output is regressed on the measured output of layer l-1 of the
*same shot* (layer 1: on x). Under reference §2 a tap is the value fed forward, so the
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
the noise of the hidden layers propagated to the output (Monte Carlo through the model, fixed
draws, at the level's fixed point): a deviation there is what every layer's deviation adds up
to, and docs/identification.md lists what cannot be separated.

Whether the map is the programmed one is a score test at the programmed map (no fit needed); a
layer with fewer inputs than its parameters per neuron (plus a margin) is not resolved: only
that test and the noise's are run there.

Every test returns a p-value (:func:`tests`: Holm-adjusted over classes x layers), an
effect size and its layer; :mod:`._mechanisms` turns them into the ``mechanisms`` list.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy import stats

from .._measurement import Measurement
from . import _memory, _time
from ._qtest import over_inputs
from ._discrete import lattice_row, resolution_var
from ._smoothing import smoothed  # noqa: F401  (the lab's modules import it from here)

#: the level at which a restricted map is rejected (model choice) and a test counts
ALPHA = 0.01
#: bins of z of the activation's shape
BINS = 8
#: a gain trend in time that carries less than this share of the gain's variance within the
#: inputs' shots is the path of a fluctuating gain, not a drift
TREND_SHARE = 0.5
#: noise levels of two layers closer than this in log s^2 (5 %: 2.5 % in s) are one level
LEVEL_TOLERANCE = 0.05
#: a layer's map is resolved (fitted, its restrictions tested) only with at least this many
#: more inputs than parameters per neuron; else only the programmed map is tested (a
#: 784-input layer at 500 inputs: W_eff cannot be read off, and its normal equations alone
#: were 2.5 GB)
RESOLVE_MARGIN = 10
#: the noise's covariance across a layer's neurons is read on at most this many of them
#: (evenly spaced): a common or correlated noise shows on any subset, and a 500-neuron layer's
#: per-input covariances would be n 500^2 floats
WIDE = 128
#: Monte Carlo draws per input of the hidden layers' noise without taps: at most this many ...
#: (the draws' error is counted: a per-input mean's variance grows by r / draws, the
#: covariance test's null by (r - 1) / (draws - 1); 2048 draws took 5 s a propagation)
MC_DRAWS = 512
#: ... within this many multiply-adds of the propagation (at least MC_MIN_DRAWS)
MC_FLOPS = 1e9
MC_MIN_DRAWS = 128
#: ... and more, where the draws' error of the per-input mean is not small against that mean's
#: spread across inputs: a regressor with an error attenuates the output's least squares by
#: spread / (spread + error) (s = 1, 512 draws: W_eff = 0.67 W, a "dead" output neuron and
#: a readout transfer named on 4 of 19 null files), so the draws grow until the error is at most
#: MC_ATTENUATION of the spread, within MC_FLOPS_MAX multiply-adds
MC_ATTENUATION = 0.05
MC_FLOPS_MAX = 1e10
#: the smooth part of the shared shape the map is tested against (Legendre degree, besides the bins)
SHAPE_DEGREE = 7
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
    Cin : (n, p, p), (p, p) (the same for every input) or None: the unit covariance (per s^2)
        of the unmeasured part of the input
    W, b : programmed weights
    hidden : whether the activation follows
    draws : the Monte Carlo draws behind A and Cin (no taps), else 0: a per-input mean of the
        residual then also carries the draws' error, a fraction r / draws of its shots'
    """

    layer: int
    A: np.ndarray
    Y: np.ndarray
    Cin: np.ndarray | None
    W: np.ndarray
    b: np.ndarray
    hidden: bool
    draws: int = 0
    #: (n, r, d) a known term of each shot's pre-activation, or None: the trend in acquisition
    #: time read within the inputs' shots (interleaved acquisition; additive or a gain), so the
    #: map is identified at t = 0 and a drift's time average is not read as a changed map
    offset: np.ndarray | None = None
    #: (2, n, d) or None: per input and neuron the model's mean sample excess kurtosis and mean
    #: Anscombe-Glynn z of r shots (no taps: read off the propagation's draws, r at a time)
    law: np.ndarray | None = None
    #: (n, d, d) or None: per input an orthonormal basis the noise's law is read in (no taps: the
    #: eigenvectors of the output's model covariance; ``law`` is in it), else the neurons
    basis: np.ndarray | None = None
    #: the smallest variance a cell's shots can be read with (:func:`~._discrete.resolution_var`):
    #: a shot's spread below it is not resolved (a quantized readout's cells of identical shots)
    res_var: float = 0.0

    @property
    def mean_factor(self) -> float:
        """How much a per-input mean residual's variance exceeds its shots' (Monte Carlo regressor)."""
        return 1.0 + (self.Y.shape[1] / self.draws if self.draws else 0.0)


def _propagate(meas: Measurement, s: float):
    """Per input, the model's mean (n, d) and unit covariance per s^2 (n, d, d) of a_{L-1}, the
    output layer's input, without taps: by Monte Carlo through the model (reference §1, awgn at
    level s), the standard normal draws fixed (the same numbers at every s), inputs in chunks.
    Exact up to the draws' error -- a linearised propagation missed the activation's curvature,
    which looked like a gain fluctuating along the signal and like correlated noise (15 % of
    null files flagged, studies/results/2026-11-25e). With ``r`` shots per input and at least
    2 r draws, also the model's law of the output's r-shot samples (:class:`_Layer` ``law``):
    the draws r at a time through the output layer, its own Gaussian noise added -- a sample's
    kurtosis at r shots, skewness terms and all, as the shots are measured. The law is read in
    each input's eigenbasis of the output's model covariance, W_L C W_L^T + I (:class:`_Layer`
    ``basis``; up to :data:`WIDE` outputs): the output's own noise is a larger share of its minor
    components than of any neuron, where the hidden layers' propagated noise dilutes a law
    change of the output's own. The draws: see :data:`MC_DRAWS` and :data:`MC_ATTENUATION`.
    Returns (mean, cov, draws, law or None, basis or None)."""
    n, p = np.shape(meas.x)
    macs = sum(np.size(W) for W, _ in meas.params[:-1]) + p
    M = int(max(MC_MIN_DRAWS, min(MC_DRAWS, MC_FLOPS / max(n * macs, 1))))
    out = _propagate_draws(meas, s, M, M)
    mean, cov = out[0], out[1]
    spread = float(np.mean(np.var(mean, axis=0)))
    err = s * s * float(np.mean(np.einsum("nii->ni", cov))) / M  # the per-input mean's variance from the draws
    if n > 1 and err > MC_ATTENUATION * spread:
        cap = int(max(M, MC_FLOPS_MAX / max(n * macs, 1)))
        want = M * err / (MC_ATTENUATION * max(spread, np.finfo(np.float64).tiny))
        M2 = int(min(cap, M * 2 ** int(np.ceil(np.log2(want / M)))))  # powers of 2: the same draws across nearby s
        if M2 > M:
            out = _propagate_draws(meas, s, M2, M)
    return out


def _propagate_draws(meas: Measurement, s: float, M: int, M_law: int):
    """:func:`_propagate` with M draws per input (the law from the first ``M_law`` of them)."""
    act = _ACT[meas.activation if meas.activation in _ACT else "tanh"][0]
    x = np.asarray(meas.x, np.float64)
    params = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in meas.params[:-1]]
    n, p = x.shape
    d = params[-1][0].shape[0]
    W_L = np.asarray(meas.params[-1][0], np.float64)
    r = meas.r
    G = min(M, M_law) // r if r >= 5 else 0
    rng = np.random.default_rng(20261127)
    rng_law = np.random.default_rng(20261128)
    chunk = max(1, int(4e6 // (M * max(p, W_L.shape[0], *(W.shape[0] for W, _ in params)))))
    mean = np.empty((n, d))
    cov = np.empty((n, d, d))
    law = np.empty((2, n, W_L.shape[0])) if G >= 2 else None
    basis = np.empty((n, W_L.shape[0], W_L.shape[0])) if W_L.shape[0] <= WIDE else None
    for c0 in range(0, n, chunk):
        xc = x[c0:c0 + chunk]
        a = xc[:, None, :] + s * rng.standard_normal((xc.shape[0], M, p))
        for W, b in params:
            zc = a @ W.T + b + s * rng.standard_normal(a.shape[:2] + (W.shape[0],))
            a = act(zc) + s * rng.standard_normal(zc.shape)
        mu = a.mean(1)
        dev = a - mu[:, None, :]
        mean[c0:c0 + chunk] = mu
        cov[c0:c0 + chunk] = np.einsum("nki,nkj->nij", dev, dev) / ((M - 1) * s * s)
        V = None
        if basis is not None:
            V = np.linalg.eigh(W_L @ cov[c0:c0 + chunk] @ W_L.T + np.eye(W_L.shape[0]))[1]
            basis[c0:c0 + chunk] = V
        if law is not None:
            v = a[:, :G * r] @ W_L.T
            v = v + s * rng_law.standard_normal(v.shape)
            if V is not None:
                v = np.matmul(v, V)
            law[:, c0:c0 + chunk] = _shots_law(v, r)
    return mean, cov, M, law, basis


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
                out.append(_Layer(1, x[:, None, :], Y, np.eye(p), W, b, L > 1, res_var=resolution_var(Y)))
            else:
                out.append(_Layer(l, np.asarray(meas.taps[l - 2], np.float64), Y, None, W, b, l < L,
                                  res_var=resolution_var(Y)))
        return out
    W, b = (np.asarray(v, np.float64) for v in meas.params[-1])
    y = np.asarray(meas.y, np.float64)
    if L == 1:
        return [_Layer(1, x[:, None, :], y, np.eye(p), W, b, False, res_var=resolution_var(y))]
    m, C, M, law, basis = _propagate(meas, s)
    return [_Layer(L, m[:, None, :], y, C, W, b, False, M, law=law, basis=basis, res_var=resolution_var(y))]


def _unit_cov(lay: _Layer, W_eff, rows=None):
    """The unit (per s^2) covariance of the pre-activation noise of each input (n, d, d), of the
    neurons ``rows`` (default all)."""
    Wr = W_eff if rows is None else W_eff[rows]
    d = Wr.shape[0]
    n = lay.Y.shape[0]
    if lay.Cin is None:
        return np.broadcast_to(np.eye(d), (n, d, d))
    if lay.Cin.ndim == 2:
        return np.broadcast_to(Wr @ lay.Cin @ Wr.T + np.eye(d), (n, d, d))
    return np.matmul(np.matmul(Wr, lay.Cin), Wr.T) + np.eye(d)


def _unit_var(lay: _Layer, W_eff):
    """The diagonal of :func:`_unit_cov` (n, d): what the means need."""
    n, d = lay.Y.shape[0], W_eff.shape[0]
    if lay.Cin is None:
        return np.ones((n, d))
    if lay.Cin.ndim == 2:
        return np.broadcast_to(np.sum((W_eff @ lay.Cin) * W_eff, axis=-1) + 1.0, (n, d))
    return np.sum(np.matmul(W_eff, lay.Cin) * W_eff, axis=-1) + 1.0


def _mean_model(lay: _Layer, act: str, W_eff, b_eff, s2, vu, tt=None, drift=None, want_var=True):
    """Per shot: the pre-activation, the model's mean, slope d mean / dz and the layer's own
    noise variance (n, r, d) at the map (W_eff, b_eff), noise level s^2 (``vu``: the unit
    variance of the pre-activation noise, (n, d), :func:`_unit_var`) and, with acquisition
    times (``tt``: t, (n, r)), the trends ``drift`` = (c, k) (d,) each: an additive
    trend c t and a gain trend k t W a of the pre-activation (the map itself is at t = 0)."""
    z = lay.A @ W_eff.T + b_eff
    if lay.offset is not None:
        z = z + lay.offset
    if tt is not None and drift is not None:
        z = z + tt[:, :, None] * (drift[0] + drift[1] * (lay.A @ lay.W.T))
    vz = s2 * vu[:, None, :]
    if lay.hidden:
        m, g, var = smoothed(act, z, np.broadcast_to(vz, z.shape), var=want_var)
        return z, m, g, (var + s2 if want_var else None)
    return z, z, np.ones_like(z), np.broadcast_to(vz, z.shape)


def _level(var_at, target: float, s2: float, iters: int = 30) -> float:
    """The level s^2 at which the model's summed cell variance ``var_at(s2)`` equals ``target``
    (the measured one). The variance grows with s^2: linearly at a small level, where the one
    step s^2 target / var_at(s^2) lands on it; where the activation's own spread saturates (s ~ 1)
    that step falls short (layer 2 of 8-16-8-4 read 1.26 at s = 1, and its kurtosis and the
    levels' test named classes on null files), so it is iterated -- the secant method in log s^2,
    its slope d log var / d log s^2 kept in [0.05, 1], to 1e-7 in log."""
    if not (target > 0 and s2 > 0):
        return s2
    x0 = np.log(s2)
    f0 = np.log(max(var_at(s2), np.finfo(np.float64).tiny)) - np.log(target)
    x1, slope = x0 - f0, 1.0
    for _ in range(iters):
        f1 = np.log(max(var_at(float(np.exp(x1))), np.finfo(np.float64).tiny)) - np.log(target)
        if abs(f1) < 1e-7:
            break
        if x1 != x0:
            slope = float(np.clip((f1 - f0) / (x1 - x0), 0.05, 1.0))
        x0, f0, x1 = x1, f1, x1 - f1 / slope
    return float(np.exp(x1))


def _cell_cov(E):
    """Per input, the covariance across shots of the residuals (n, d, d) (ddof 1)."""
    r = E.shape[1]
    c = E - E.mean(1, keepdims=True)
    return np.einsum("nki,nkj->nij", c, c) / max(r - 1, 1)


def _cell_var(E, floor: float = 0.0):
    """Per input, the variance across shots of each neuron's residual (n, d) (ddof 1): the
    diagonal of :func:`_cell_cov` without its d^2 floats per input; at least ``floor`` (the
    layer's resolution: cells of identical shots weigh as much as the data can tell, not
    1 / 1e-300)."""
    v = np.var(E, axis=1, ddof=1) if E.shape[1] > 1 else np.zeros((E.shape[0], E.shape[2]))
    return np.maximum(v, floor)


def _subset(d: int) -> np.ndarray:
    """The neurons whose covariance is read: all, or :data:`WIDE` evenly spaced."""
    return np.arange(d) if d <= WIDE else np.unique(np.linspace(0, d - 1, WIDE).round().astype(int))


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


def _gram(X, w=None):
    """Per neuron ``sum_n w[n, i] X[n, i, p] X[n, i, q]`` as (d, k, k), by batched matrix
    products on strided views (BLAS takes the row stride; numpy's einsum of these indices runs
    its own loops, 2.3 times slower at 50 neurons x 400 inputs, and contiguous copies first
    cost 5-10 times the product)."""
    Xn = X.transpose(1, 0, 2)  # (d, n, k), a view
    return np.matmul(Xn.transpose(0, 2, 1), Xn if w is None else (X * w[:, :, None]).transpose(1, 0, 2))


def _meat(C, X):
    """sum_n C[n, i, j] X[n, i, p] X[n, j, q] as (d, k, d, k): batched matrix products over
    blocks of neurons i (an einsum over four indices ran at a tenth of BLAS' pace)."""
    n, d, k = X.shape
    out = np.empty((d, k, d, k))
    chunk = max(1, int(4e6 // max(n * d * k, 1)))
    for i0 in range(0, d, chunk):
        sl = slice(i0, min(i0 + chunk, d))
        Y = C[:, sl, :, None] * X[:, None, :, :]  # (n, c, d, k)
        c = Y.shape[1]
        out[sl] = np.matmul(X[:, sl, :].transpose(1, 2, 0),
                            Y.transpose(1, 0, 2, 3).reshape(c, n, d * k)).reshape(c, k, d, k)
    return out


def _covariance(X, Chat, obs, r):
    """The sandwich covariance of the stacked per-neuron least squares (d (p+1) square), or
    its per-neuron blocks (d, p+1, p+1) when the layer is wide (``Chat``: per input the
    residuals' covariance across neurons, needed only then; ``obs`` its diagonal; ``r`` the
    shots a per-input mean averages)."""
    n, d, k = X.shape
    Binv = np.linalg.inv(_gram(X) + 1e-12 * np.eye(k))
    if d * k <= FULL_COV_MAX:
        meat = _meat(Chat / r, X)
        S = np.matmul(Binv, meat.transpose(2, 0, 1, 3))  # (j, i, a, c): Binv_i meat_ij
        S = np.matmul(S, Binv.transpose(0, 2, 1)[:, None])  # (j, i, a, d): ... Binv_j^T
        return S.transpose(1, 2, 0, 3).reshape(d * k, d * k), True
    # Binv_i meat_i Binv_i^T per neuron (a three-operand einsum loops over all five indices:
    # d k^4 steps, hours on a 785-input layer; two batched products are 2 d k^3)
    T = np.matmul(Binv, _gram(X, obs / r))
    return np.matmul(T, Binv.transpose(0, 2, 1)), False


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
    if tt is not None:  # the trends free: both the residual and the design projected off them
        XT, X = X[:, :, p + 1:], X[:, :, :p + 1]
        Gi = np.linalg.inv(np.einsum("nia,nib->iab", XT, XT) + 1e-12 * np.eye(XT.shape[2]))
        e = e - np.einsum("nia,ia->ni", XT, np.einsum("iab,ib->ia", Gi, np.einsum("nib,ni->ib", XT, e)))
        X = X - np.einsum("nia,iac->nic", XT, Gi @ np.einsum("nib,nic->ibc", XT, X))
    alive = np.asarray(alive, int)
    if alive.size == 0:
        return 1.0, 0.0
    e, X = e[:, alive], X[:, alive]
    da, kk = X.shape[1], X.shape[2]
    U = np.einsum("nip,ni->ip", X, e)
    if Chat is not None and da * kk <= FULL_COV_MAX:
        Ca = Chat[:, alive][:, :, alive]
        V = _meat(Ca / r, X).reshape(da * kk, da * kk)
        w, Q = np.linalg.eigh(V)
        keep = w > 1e-10 * max(w.max(), 1e-300)
        q = float(np.sum((Q[:, keep].T @ U.ravel()) ** 2 / w[keep]))
        return _chi2(q, int(keep.sum()), nu)
    ps = np.empty(da)
    for a_, i in enumerate(alive):
        Xi = X[:, a_]
        w, Q = np.linalg.eigh(Xi.T @ (Xi * (obs[:, i] / r)[:, None]))
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
    da, k = X.shape[1], X.shape[2]
    if tt is not None:  # the time trends are nuisance parameters too, per neuron (as in the omnibus)
        XT, X = X[:, :, p + 1:], X[:, :, :p + 1]
        Gi = np.linalg.inv(np.einsum("nia,nib->iab", XT, XT) + 1e-12 * np.eye(XT.shape[2]))
        e = e - np.einsum("nia,ia->ni", XT, np.einsum("iab,ib->ia", Gi, np.einsum("nib,ni->ib", XT, e)))
        X = X - np.einsum("nia,iac->nic", XT, Gi @ np.einsum("nib,nic->ibc", XT, X))
        H = H - np.einsum("nia,iac->nic", XT, Gi @ np.einsum("nib,nic->ibc", XT, H))
        k = X.shape[2]
    # stacked over (input, neuron): the map's design B is block-diagonal over neurons (neuron i's
    # row of input n is X[n, i] in its own block), the shape's columns H are shared; both are
    # projected off the shape's span, B' = B - H G with G = (H'H)^+ H'B of rank <= the shape's
    # columns, so the score's covariance sum_n B'_n^T C_n B'_n is the sandwich meat of B plus
    # low-rank terms (never the dense (n da) x (da k) design)
    Hs = H.reshape(n * da, -1)
    Pi = np.linalg.pinv(Hs.T @ Hs)
    G = Pi @ np.einsum("nib,nik->bik", H, X).reshape(H.shape[2], da * k)  # (c, da k)
    es = e - H @ (Pi @ (Hs.T @ e.reshape(-1)))  # (n, da)
    U = np.einsum("nik,ni->ik", X, es).reshape(-1) - G.T @ (Hs.T @ es.reshape(-1))
    Ca = Chat[:, alive][:, :, alive] / r
    CH = np.matmul(Ca, H)  # (n, da, c)
    HCB = np.einsum("nic,nik->cik", CH, X).reshape(H.shape[2], da * k)  # sum_n H_n^T C_n B_n
    HCH = np.einsum("nic,nid->cd", H, CH)
    V = (_meat(Ca, X).reshape(da * k, da * k) - G.T @ HCB - HCB.T @ G + G.T @ HCH @ G)
    w, Q = np.linalg.eigh(V)
    keep = w > 1e-10 * max(w.max(), 1e-300)
    q = float(np.sum((Q[:, keep].T @ U) ** 2 / w[keep]))
    return _chi2(q, int(keep.sum()), nu)[0]


def _solve_psd(S, v):
    try:
        return np.linalg.solve(S, v)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(S) @ v


class _Blocks:
    """A block-diagonal covariance (one (k, k) block per neuron) of the stacked theta: what a wide
    layer's map has (dense, 100 neurons of 101 parameters were 10^4 x 10^4 floats and a solve of
    10^12 operations)."""

    def __init__(self, blocks):
        self.blocks = blocks
        self.k = blocks.shape[1]

    def sub(self, idx):
        """The dense covariance of the entries ``idx`` (a few hundred at most)."""
        i, a = np.divmod(np.asarray(idx), self.k)
        return np.where(i[:, None] == i[None, :], self.blocks[i[:, None], a[:, None], a[None, :]], 0.0)

    def diag(self):
        return np.einsum("iaa->ia", self.blocks).ravel()


def _sub(S, idx):
    return S.sub(idx) if isinstance(S, _Blocks) else S[np.ix_(idx, idx)]


def _gls(theta, S, R):
    """GLS of theta ~ N(R phi, S): phi, its covariance and the misfit chi-square."""
    if isinstance(S, _Blocks):
        d, k = S.blocks.shape[:2]
        Sinv = np.linalg.pinv(S.blocks, hermitian=True)
        Rb = R.reshape(d, k, R.shape[1])
        SiR = np.matmul(Sinv, Rb)
        F = np.einsum("iam,ian->mn", Rb, SiR)
        Fi = np.linalg.pinv(F)
        tb = theta.reshape(d, k)
        phi = Fi @ np.einsum("iam,ia->m", SiR, tb)
        q_full = float(np.einsum("ia,iab,ib->", tb, Sinv, tb))
        return phi, Fi, max(q_full - float(phi @ F @ phi), 0.0)
    return _gls_solved(theta, R, _solve_psd(S, np.column_stack([R, theta])))


def _gls_solved(theta, R, Si):
    """:func:`_gls` given S^-1 [R, theta] (one solve serves several R's sharing columns)."""
    Si_R = Si[:, :-1]
    F = R.T @ Si_R
    Fi = np.linalg.pinv(F)
    phi = Fi @ (Si_R.T @ theta)
    q_full = float(theta @ Si[:, -1])
    return phi, Fi, max(q_full - float(phi @ F @ phi), 0.0)


def _gls_all(theta, S, models: dict) -> dict:
    """:func:`_gls` for each restriction of ``models`` (name: R), the dense S solved once for
    all of them."""
    if isinstance(S, _Blocks):
        return {name: _gls(theta, S, R) for name, R in models.items()}
    Rs = list(models.values())
    Si = _solve_psd(S, np.column_stack(Rs + [theta]))
    out, c0 = {}, 0
    for name, R in models.items():
        m = R.shape[1]
        out[name] = _gls_solved(theta, R, np.column_stack([Si[:, c0:c0 + m], Si[:, -1]]))
        c0 += m
    return out


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
        "transfer", "bias", "gain+bias", "rows" (per-neuron gain and shift of z), "detector" (a hidden
        neuron's own gain and offset after the activation, when no map of z fits) or "general";
        "unresolved" when the layer has too few inputs for its parameters (W_eff is then W and
        theta_se infinite: only the programmed map as a whole and the noise are tested)
    z_bins : (B,) centres of the bins of z; shape : (B,) the binned mean residual shared by the
        neurons beyond their affine maps (the activation's shape deviation); curve : (d, B) per
        neuron the binned mean residual against the programmed z (a flat neuron is dead)
    s : the layer's own noise level; s_se its standard error
    kurtosis : mean excess kurtosis of the standardised shots beyond the model's (0 for its Gaussian law)
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


def _ag_z(b2, r: int):
    """Anscombe and Glynn's (1983) normalising transform of a sample kurtosis b2 = m4 / m2^2 of r
    values (r >= 5): near N(0, 1) for a normal sample (``scipy.stats.kurtosistest``'s statistic),
    its skewness 0.14 at r = 16 where b2's own is ~3. A mean over cells of b2 is dominated by
    its right tail, and a test over inputs of it was not calibrated at 80 inputs (the t-statistic
    of a skewed quantity: no-taps null files rejected at 0.01 on 5 % of random networks)."""
    b2 = np.asarray(b2, np.float64)
    E = 3.0 * (r - 1) / (r + 1)
    varb2 = 24.0 * r * (r - 2) * (r - 3) / ((r + 1) ** 2 * (r + 3) * (r + 5))
    x = (b2 - E) / np.sqrt(varb2)
    sb1 = 6.0 * (r * r - 5 * r + 2) / ((r + 7) * (r + 9)) * np.sqrt(6.0 * (r + 3) * (r + 5) / (r * (r - 2) * (r - 3)))
    A = 6.0 + 8.0 / sb1 * (2.0 / sb1 + np.sqrt(1.0 + 4.0 / sb1 ** 2))
    denom = 1.0 + x * np.sqrt(2.0 / (A - 4.0))
    term2 = np.sign(denom) * np.cbrt((1.0 - 2.0 / A) / np.maximum(np.abs(denom), 1e-300))
    return (1.0 - 2.0 / (9.0 * A) - term2) / np.sqrt(2.0 / (9.0 * A))


def _sample_law(x, r: int):
    """(2, ...): the sample excess kurtosis and its Anscombe-Glynn z of the r values along the
    last axis of ``x`` (r >= 5)."""
    x = x - x.mean(-1, keepdims=True)
    x = x * x  # squares (x ** 4 is a general power in numpy: 20 times slower than a square of squares)
    m2 = np.mean(x, -1)
    b2 = np.mean(x * x, -1) / np.maximum(m2 * m2, 1e-300)
    return np.stack([b2 - 3.0, _ag_z(b2, r)])


def _shots_law(shots, r: int):
    """(2, n, d): per input and neuron the mean of :func:`_sample_law` over the K // r samples of
    r consecutive shots of ``shots`` (n, K, d) -- a measurement's r shots (one sample) or a
    model's K."""
    n, K, d = shots.shape
    x = np.asarray(shots, np.float64)[:, :K // r * r].reshape(n, K // r, r, d)
    return _sample_law(np.moveaxis(x, 2, -1), r).mean(2)


def _expected_kurtosis(act: str | None, z, vz, s2: float, r: int):
    """Per input and neuron (2, n, d), ``z`` (n, d) or per shot (n, r, d): the mean sample excess kurtosis (m4 / m2^2 - 3 of r shots,
    as measured) and the mean of its Anscombe-Glynn z (:func:`_ag_z`) of
    sigma(z + sqrt(vz) xi) + s eta, xi and eta standard normal -- a Gaussian pre-activation noise
    bent by the activation plus the layer's own output noise; ``act`` None: z + sqrt(vz) xi, a
    Gaussian layer without activation -- by Monte Carlo, independent draws per cell (fixed seed).
    A sample's kurtosis is biased at r shots by -6/(r+1) for a normal law and by terms in the
    skewness for a bent one; both are here (the law's own kurtosis alone, by quadrature, left
    layer 1 of 12-24-12-6 flagged on 4 % of null files at 0.01)."""
    f = _ACT[act][0] if act is not None else None
    # z per shot (n, r, d): the regressor moves within the input (taps), and the cell's law is the
    # mixture of each shot's own, each shot's deviation standardised by its own variance as the
    # measured ones are (at s = 1 the law at the cell's mean z named noise_law on null files)
    per_shot = z.ndim == 3 and f is not None
    if z.ndim == 3:
        z = np.moveaxis(z, 1, 2) if per_shot else z.mean(1)
    n, d = z.shape[:2]
    # draws per cell: few are enough -- the Monte Carlo error is independent across inputs, so
    # the test over inputs counts it in its own variance (calibrated at any B, a little less
    # power at small B); 2e6 samples per layer keep it at ~0.1 s (3e7 took 4 s a layer)
    B = int(max(4, min(32, 2e6 / max(n * d * r, 1))))
    rng = np.random.default_rng(20261127)
    sd, s_ = np.sqrt(np.maximum(vz, 0.0)), np.sqrt(s2)
    out = np.empty((2, n, d))
    chunk = max(1, int(4e6 // max(d * B * r, 1)))
    for c0 in range(0, n, chunk):
        zc = z[c0:c0 + chunk, :, None, :] if per_shot else z[c0:c0 + chunk, :, None, None]
        sc = sd[c0:c0 + chunk, :, None, None]
        shape = zc.shape[:2] + (B, r)
        x = (f(zc + sc * rng.standard_normal(shape)) + s_ * rng.standard_normal(shape) if f is not None
             else sc * rng.standard_normal(shape))
        if per_shot:
            mk, _, vk = smoothed(act, zc, np.broadcast_to(sc * sc, zc.shape))
            x = (x - mk) / np.sqrt(vk + s2)
        out[:, c0:c0 + chunk] = _sample_law(x, r).mean(-1)
    return out


def _expected_kurtosis_signal(act: str | None, z, u, vz, var, r: int, signal: tuple):
    """:func:`_expected_kurtosis` of the residuals of a layer whose noise variance changes with
    the signal (``signal`` of :func:`_signal_variance`): each shot at its own pre-activation ``z``
    (n, r, d) -- with taps the input changes from shot to shot, and so does a shot's variance --
    the value v = sigma(z + sqrt(vz') xi) + s eta (``act`` None: z + sqrt(vz') xi) less its mean
    given z, plus a readout noise sqrt(q |v|) zeta (form "readout": shot noise, a scale mixture
    with tails of its own at equal variance) or with vz' = vz + m^2 u^2 (form "pre-activation",
    ``u`` (n, r, d) each shot's weighted sum: a Gaussian pre-activation of a larger variance);
    ``vz`` (n, d) the pre-activation's unit variance; ``var`` (n, r, d) the variance each measured
    shot was divided by (the model's at its level), each drawn shot divided by it too."""
    form, s2a, c1 = signal
    f = _ACT[act][0] if act is not None else None
    n, d = vz.shape
    z, u, var = (np.broadcast_to(a_, (n, r, d)) for a_ in (z, u, var))  # layer 1: one input per cell, r shots
    B = int(max(4, min(32, 2e6 / max(n * d * r, 1))))
    rng = np.random.default_rng(20261129)
    out = np.empty((2, n, d))
    chunk = max(1, int(4e6 // max(d * B * r, 1)))
    for c0 in range(0, n, chunk):
        zc = np.moveaxis(z[c0:c0 + chunk], 1, 2)[:, :, None, :]  # (c, d, 1, r): each shot its own z
        vc = vz[c0:c0 + chunk][:, :, None, None] + (c1 / s2a * np.moveaxis(u[c0:c0 + chunk], 1, 2)[:, :, None, :] ** 2
                                                    if form != "readout" else 0.0)
        sc = np.sqrt(s2a * np.maximum(vc, 0.0))
        shape = zc.shape[:2] + (B, r)
        if f is not None:
            v = f(zc + sc * rng.standard_normal(shape)) + np.sqrt(s2a) * rng.standard_normal(shape)
            x = v - smoothed(act, zc, sc * sc, var=False)[0]
        else:
            x = sc * rng.standard_normal(shape)
            v = zc + x
        if form == "readout":
            x = x + np.sqrt(c1 * np.abs(v)) * rng.standard_normal(shape)
        x = x / np.sqrt(np.maximum(np.moveaxis(var[c0:c0 + chunk], 1, 2)[:, :, None, :], 1e-300))
        out[:, c0:c0 + chunk] = _sample_law(x, r).mean(-1)
    return out


def _signal_variance(obs, vcell, absv, pre2, s2: float) -> tuple:
    """The layer's noise variance fitted as a function of the signal, ``(form, c0, c1)``: each
    cell's observed variance ``obs`` (n, d) against ``c0 vcell + c1 x`` by non-negative least
    squares relative to the model's ``s2 vcell``, x either the readout value's ``absv`` = E|v|
    (shot noise, form "readout") or the squared pre-activation signal ``pre2`` (a fluctuating
    gain on the weighted sum, form "pre-activation": a Gaussian pre-activation of a larger
    variance), whichever leaves the smaller residual. c0 is the additive level s^2 left."""
    from scipy.optimize import nnls

    w = 1.0 / np.maximum(s2 * vcell, 1e-300).ravel()
    y = obs.ravel() * w
    best = None
    for form, x in (("readout", absv), ("pre-activation", pre2)):
        A = np.stack([vcell.ravel() * w, np.asarray(x, np.float64).ravel() * w], axis=1)
        coef, res = nnls(A, y)
        if best is None or res < best[0]:
            best = (res, form, float(coef[0]), float(coef[1]))
    return best[1:]


def _curve(lay: _Layer, act: str, s2: float):
    """(d, BINS): per neuron the binned mean residual against the programmed z (the
    nonparametric curve, for the evidence: a dead neuron's is -tanh(z))."""
    z0 = lay.A @ lay.W.T + lay.b  # as _mean_model's z (a BLAS product; the einsum ran at half its pace)
    res0 = lay.Y - _mean_model(lay, act, lay.W, lay.b, s2, _unit_var(lay, lay.W))[1]
    e0 = np.quantile(z0, np.linspace(0, 1, BINS + 1))
    e0[0], e0[-1] = -np.inf, np.inf
    i0 = np.clip(np.searchsorted(e0, z0, side="right") - 1, 0, BINS - 1)
    i0 = np.broadcast_to(i0, res0.shape)
    return np.stack([np.sum(np.where(i0 == j, res0, 0.0), axis=(0, 1)) / np.maximum(np.sum(i0 == j, axis=(0, 1)), 1)
                     for j in range(BINS)], axis=-1)


def _noise_rows(lay: _Layer, act: str, l: int, t, E, obs, Chat_s, sub, z, g, var, b_eff, s2: float, vz, Czu_s,
                E_time=None):
    """The noise's tests at one layer from the within-input residuals ``E`` (n, r, d) and their
    variances ``obs`` (n, d); the covariance across neurons ``Chat_s`` on the neurons ``sub``
    (with the model's unit covariance ``Czu_s`` there); ``var`` the model's variance of each
    shot, ``vz`` the unit variance of the pre-activation noise (n, d). Returns (rows, s, s_se,
    excess kurtosis beyond the model's)."""
    n, r, d = E.shape
    rows = []
    vcell = (var / s2).mean(1)  # (n, d) unit variance of a cell
    u = (z.mean(1) - b_eff)  # the weighted sum
    wg = (g.mean(1) * u) if lay.hidden else u  # how the layer's output moves with a gain on it
    # the level: observed over unit variances of the cells; its error over inputs
    Tl = np.sum(obs - s2 * vcell, axis=1)
    s_lvl = float(np.sqrt(s2))
    s_se = float(np.sqrt(n * np.var(Tl, ddof=1)) / max(np.sum(vcell), 1e-300) / (2 * s_lvl))
    # variance against the neuron's own signal and the input's energy
    rho = obs / np.maximum(s2 * vcell, 1e-300) - 1.0
    own = np.abs(z).mean(1)
    own = own - own.mean(0)
    energy = np.sum(lay.A ** 2, axis=2).mean(1)
    energy = energy - energy.mean()
    z_own = over_inputs(np.sum(rho * own, 1))
    z_en = over_inputs(rho.mean(1) * energy) if np.std(energy) > 0 else 0.0
    # ... and the neuron's weighted sum |u| (a noise on the weighted sum, s (1 + beta |u|) or a
    # multiplicative gain's m^2 u^2: z = u + b, and a bias of either sign hides it from |z|)
    own_u = np.abs(u) - np.abs(u).mean(0) if lay.hidden else own
    z_u = over_inputs(np.sum(rho * own_u, 1)) if lay.hidden else 0.0
    zs_ = {"the neuron's own |z|": z_own, "the input's energy |a_{l-1}|^2": z_en, "the weighted sum |u|": z_u}
    which = max(zs_, key=lambda k: abs(zs_[k]))
    zi = abs(zs_[which])
    slope_own = float(np.sum(rho * own) / max(np.sum(own ** 2), 1e-300))
    p_signal = min(1.0, (3 if lay.hidden else 2) * _two_sided(zi))
    rows.append(_row("input_dependent_noise", "variance", p_signal, zi,
                     slope_own, f"the noise variance at layer {l} changes with {which} (z = {z_own:.1f} own "
                     f"signal |z|, {z_u:.1f} weighted sum, {z_en:.1f} input energy)"))
    # the law is tested at the variance the data show: where it changes with the signal (that
    # test rejects), against the model with that dependence fitted -- shot noise's variance
    # q |v| makes a scale mixture with tails of its own, and a pure shot-noise file was named
    # noise_law at z = 11 (kurtosis +0.44 at the output) beside input_dependent_noise
    # (signal: (form, the additive s^2 left, q of q |v| or m^2 of m^2 u^2 in the pre-activation);
    # a hidden layer's output moves by g u where its pre-activation moves by u, each shot's own u)
    signal = (_signal_variance(obs, vcell, np.abs(lay.Y).mean(1),
                               (((g if lay.hidden else 1.0) * (z - b_eff)) ** 2).mean(1), s2)
              if p_signal < ALPHA and lay.law is None else None)
    if signal is not None and (signal[1] <= 0.0 or signal[2] <= 0.0):
        signal = None
    kz, kurt, k_exp = 0.0, 0.0, np.full((n, d), -6.0 / (r + 1))
    if r >= 5:
        # per cell the sample kurtosis and its normalising transform; the model's own law of r
        # shots: an activation bends a Gaussian pre-activation noise into a law of its own
        # (layer 1: the input's noise through W as well; no taps: the hidden layers' noise
        # propagated), and a normal sample's kurtosis is biased by -6/(r+1) (before the model's
        # was subtracted: layer 1 of 12-24-12-6 flagged on 15 % of null files)
        if lay.basis is not None:  # the model covariance's components (kurtosis: no scale needed)
            dev = np.matmul(E - E.mean(1, keepdims=True), lay.basis)
        else:  # each neuron, a shot by its own variance
            dev = (E - E.mean(1, keepdims=True)) / np.sqrt(np.maximum(var, 1e-300))
        k_cell = _shots_law(dev, r)
        if lay.law is not None:
            law = lay.law
        elif signal is None:
            law = _expected_kurtosis(act if lay.hidden else None, z if lay.A.shape[1] > 1 else z.mean(1), s2 * vz,
                                     s2, r)
        else:
            law = _expected_kurtosis_signal(act if lay.hidden else None, z, z - b_eff, vz, var if lay.basis is None
                                            else np.ones_like(var), r, signal)
        k_exp = law[0]
        kz = over_inputs((k_cell[1] - law[1]).mean(1))
        kurt = float(np.mean(k_cell[0] - k_exp))
    rows.append(_row("noise_law", "kurtosis", _two_sided(kz), abs(kz), kurt,
                     f"excess kurtosis {kurt:+.2f} of the "
                     + ("output's noise along its model covariance's eigenvectors" if lay.basis is not None
                        else "standardised shots") + f" at layer {l} beyond the model's "
                     f"{float(np.mean(k_exp)) + 6.0 / (r + 1):+.2f} (0 for a Gaussian law; the model's: its Gaussian "
                     f"noise bent by the activation" + (f", with the variance fitted to the signal ({signal[0]}: "
                                                        f"{signal[2]:.3g} {'|v|' if signal[0] == 'readout' else 'u^2'}"
                                                        f" on top of s = {np.sqrt(signal[1]):.3g})"
                                                        if signal is not None else "") + ")"))
    # covariance across the layer's neurons within a shot, beyond the model's, on the neurons
    # ``sub`` (all of a layer up to WIDE)
    ds = len(sub)
    gain_var = 0.0
    gs, wgs, obs_s = g.mean(1)[:, sub], wg[:, sub], obs[:, sub]
    if ds > 1:
        off = 1 - np.eye(ds)
        # the model's off-diagonal pattern (layer 1, no taps: the unmeasured input noise through W),
        # its scale fitted (a level misjudged elsewhere must not look like a correlation)
        M = (gs[:, :, None] * (Czu_s - np.eye(ds)) * gs[:, None, :]) if lay.hidden else (Czu_s - np.eye(ds))
        M = np.broadcast_to(M, Chat_s.shape) * off
        mm = float(np.sum(M * M))
        Cm = (float(np.sum(Chat_s * M)) / mm) * M if mm > 0 else np.zeros_like(Chat_s)

        def along(w):
            w = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
            a = np.einsum("ni,nij,nj->n", w, (Chat_s - Cm) * off, w)
            b_ = np.einsum("ni,ni->n", w * w, obs_s)
            return over_inputs(a / np.maximum(b_, 1e-300)), w, a

        z_g, wn, a_g = along(wgs)
        # the relative gain variance that excess covariance amounts to: C_ij = v w_i w_j off the
        # diagonal (w: how the output moves with the gain), v by least squares over the inputs
        Cex = (Chat_s - Cm) * off
        ww = wgs[:, :, None] * wgs[:, None, :] * off
        gain_var = float(np.sum(Cex * ww) / max(np.sum(ww * ww), 1e-300))
        rows.append(dict(_row("gain_fluctuation", "common_gain", stats.norm.sf(z_g), z_g, z_g,
                              f"excess covariance along the signal at layer {l} (z = {z_g:.1f}): a gain shared by "
                              f"the neurons, fluctuating from shot to shot"), variance=gain_var))
        z1 = along(np.ones((n, ds)))[0]
        z_s = along(gs)[0] if lay.hidden else z1
        # any correlation beyond the signal's direction: the off-diagonal covariance, less a fitted
        # rank-one part along the signal, squared, beyond its null size
        # <Q, Q> = 1 - sum w^4 is 0 where the signal sits on one neuron (a saturated layer): no
        # off-diagonal part to fit there (a_g / 1e-300 overflowed)
        den = 1.0 - np.sum(wn ** 4, 1)
        alpha = np.where(den > 1e-12, a_g / np.where(den > 1e-12, den, 1.0), 0.0)
        dC = (Chat_s - Cm - alpha[:, None, None] * wn[:, :, None] * wn[:, None, :]) * off
        # The rank-one part fitted per input, alpha Q with Q = w w^T off the diagonal, absorbs
        # its share of the sampling error e of the off-diagonal covariance: what is left has
        # expectation sum_{i != j} E e_ij^2 - E <e, Q>^2 / <Q, Q>, and for r shots of covariance
        # C (Wishart) E e_ij^2 = (C_ii C_jj + C_ij^2) / (r - 1), E <e, Q>^2 = 2 tr(Q C Q C) / (r - 1)
        # -- the pairs' errors are correlated, strongly where a narrow layer upstream makes the
        # output's noise nearly low-rank, and the projection takes more than its one pair's
        # worth there (U's mean -0.19 on a 12-output null file after a 4-neuron layer; without
        # any of this, z = -2.5 on average over 60 random null networks, and no power). A layer
        # of two neurons has nothing left (not tested).
        Cfull = Cm + obs_s[:, :, None] * np.eye(ds)
        Q = wn[:, :, None] * wn[:, None, :] * off
        QQ = np.maximum(np.sum(Q * Q, axis=(1, 2)), 1e-300)

        def expected_left(C, dof):
            v = np.diagonal(C, axis1=-2, axis2=-1)
            total = np.sum((v[:, :, None] * v[:, None, :] + C ** 2) * off, axis=(1, 2))
            QC = Q @ C
            return (total - 2.0 * np.einsum("nij,nji->n", QC, QC) / QQ) / dof

        left = expected_left(Cfull, max(r - 1, 1))
        if lay.draws > 1 and not lay.hidden:
            # without taps the model's covariance is a Monte Carlo estimate too, its own error
            # part of dC's: M draws of the hidden layers' propagated part H of the output's
            # covariance (its diagonal h; the output's own noise is exact, and counting it here
            # too put U's mean at -0.09 on a 9-output null file)
            h = np.broadcast_to((float(np.sum(Chat_s * M)) / mm if mm > 0 else 0.0)
                                * (np.diagonal(Czu_s, axis1=-2, axis2=-1) - 1.0), obs_s.shape)
            left = left + expected_left(Cm + h[:, :, None] * np.eye(ds), lay.draws - 1)
        elif lay.draws > 1:
            left = left * (1.0 + max(r - 1, 1) / (lay.draws - 1))
        U = (np.sum(dC ** 2, axis=(1, 2)) - left) / np.maximum(left, 1e-300)
        z_u = over_inputs(U) if ds > 2 else -np.inf
        zc_ = max(z1, z_s, z_u)
        what = ("along all neurons alike (common additive noise)" if zc_ == z1 else
                "along sigma'(z) (common noise before the activation)" if zc_ == z_s else
                "in a pattern beyond the signal's direction")
        rows.append(dict(_row("correlated_noise", "correlation", min(1.0, 3 * stats.norm.sf(zc_)), zc_, zc_,
                              f"noise correlated across the neurons of layer {l} {what} (z = {z1:.1f} common"
                              + (f", {z_u:.1f} any pattern)" if ds > 2 else ")")
                              + (f"; read on {ds} of its {d} neurons" if ds < d else "")),
                         z_common=float(z1), z_pattern=float(z_u) if ds > 2 else None))
    if t is not None and r > 2 and np.std(t - t.mean(1, keepdims=True)) > 0:
        # trends within an input's shots (acquisition order interleaved across inputs): the
        # within-input residuals against t - its input's mean, additive per neuron and a gain
        tw = t - t.mean(1, keepdims=True)
        Es = (E if E_time is None else E_time)[:, :, sub]
        Ed = Es - Es.mean(1, keepdims=True)
        gk = np.broadcast_to(g[:, :, sub], Es.shape)
        rows_t = []
        for name, D in (("additive", gk * tw[:, :, None]), ("gain", gk * np.broadcast_to(u[:, None, sub], Es.shape)
                                                              * tw[:, :, None])):
            S_ = np.sum(D * D, axis=(0, 1))
            beta = np.sum(D * Ed, axis=(0, 1)) / np.maximum(S_, 1e-300)
            MD = np.einsum("nki,nkj->nij", D, D)
            Cb = np.einsum("nij,nij->ij", MD, Chat_s) / np.maximum(np.outer(S_, S_), 1e-300)
            if name == "additive":
                q = float(beta @ _solve_psd(Cb, beta))
                rows_t.append((name, *_chi2(q, ds), beta, Cb))
            else:  # one relative gain trend shared by the neurons: the precision-weighted mean
                wv = 1.0 / np.maximum(np.diag(Cb), 1e-300)
                wv = wv / wv.sum()
                kb = float(wv @ beta)
                zk = kb / np.sqrt(max(float(wv @ Cb @ wv), 1e-300))
                rows_t.append((name, _two_sided(zk), abs(zk), beta, Cb))
        best = min(rows_t, key=lambda x: x[1])
        zc_ = best[3] / np.sqrt(np.maximum(np.diag(best[4]), 1e-300))
        wi = int(np.argmax(np.abs(zc_)))
        row = _row("time_drift", "time_within", min(1.0, 2 * best[1]), best[2], float(best[3][wi]),
                   f"within the inputs' shots, layer {l} moves with acquisition time: {best[0]} trend "
                   f"{best[3][wi]:+.3g} per unit t at {l}:{int(sub[wi])} (z = {zc_[wi]:.1f}; the layer's "
                   f"z = {best[2]:.1f})", [int(sub[wi])])
        if best[0] == "gain" and ds > 1 and gain_var > 0:
            # how much of the gain's variance within an input's shots the trend carries: a drift
            # carries all of it, a gain fluctuating on a time scale shorter than the campaign
            # (an AR(1) laser) little -- its realised path has a trend too
            wv = 1.0 / np.maximum(np.diag(best[4]), 1e-300)
            kb = float((wv / wv.sum()) @ best[3])
            share = min(1.0, kb * kb * float(np.mean(tw * tw)) / gain_var)
            row = dict(row, share=share, evidence=row["evidence"] + f"; the trend carries {share:.0%} of the "
                       "gain's variance within the inputs' shots")
        rows.append(row)
    if t is not None and np.std(t.mean(1)) > 0:
        tc = t.mean(1) - t.mean()
        z_vt = over_inputs(tc * rho.mean(1))
        rows.append(_row("time_drift", "time_noise", _two_sided(z_vt), abs(z_vt), z_vt,
                         f"the noise level at layer {l} moves over acquisition time (z = {z_vt:.1f})"))
    return rows, s_lvl, s_se, kurt


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


def _unresolved_layer(lay: _Layer, act: str, s_guess: float, t, k: int, why: str = "") -> LayerIdentity:
    """A layer with too few inputs for its map (n < k + RESOLVE_MARGIN parameters per neuron):
    W_eff cannot be read off. The programmed map is tested as a whole -- each neuron's per-input
    mean residual at it, standardised by its shots (a mean of F(1, r - 1) terms, Student t over
    inputs; the largest over neurons, Bonferroni) -- and the noise is identified at it; the map's
    form (gain, bias, shape, dead neurons) is not resolved (``choice`` "unresolved")."""
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    l = lay.layer
    if t is not None:
        t = np.asarray(t, np.float64)
    vz = _unit_var(lay, lay.W)
    s2 = s_guess ** 2
    for _ in range(3):  # the level (the smoothing depends on it at second order only)
        z, m, g, var = _mean_model(lay, act, lay.W, lay.b, s2, vz)
        obs = _cell_var(lay.Y - m, lay.res_var)
        s2 = _level(lambda v: float(np.sum(_mean_model(lay, act, lay.W, lay.b, v, vz)[3].mean(1))), float(np.sum(obs)),
                    s2)
    z, m, g, var = _mean_model(lay, act, lay.W, lay.b, s2, vz)
    E = lay.Y - m
    obs = _cell_var(E, lay.res_var)
    rows = []
    e = E.mean(1)
    rel = float(np.sqrt(np.mean(e ** 2)) / max(np.sqrt(np.mean(obs)), 1e-300))
    if r >= 5:
        T = e * e * r / np.maximum(obs * lay.mean_factor, 1e-300) - (r - 1) / (r - 3)
        zs = np.array([over_inputs(T[:, i]) for i in range(d)])
        j = int(np.argmax(zs))
        pm = float(min(1.0, d * stats.norm.sf(zs[j])))
        rows.append(_row("weight_error", "omnibus", pm, _z_of_p(pm) if pm < 1.0 else 0.0, rel,
                         f"the per-input means at layer {l} against its programmed map: largest departure at "
                         f"{l}:{j} (z = {zs[j]:.1f}, p = {pm:.2g} over {d} neurons); the map's form is not resolved "
                         f"({why or f'{k} parameters per neuron from {n} inputs'})", [j]))
    sub = _subset(d)
    noise_rows, s_lvl, s_se, kurt = _noise_rows(lay, act, l, t, E, obs, _cell_cov(E[:, :, sub]), sub, z, g, var,
                                                lay.b, s2, vz, _unit_cov(lay, lay.W, sub))
    rows.extend(noise_rows)
    nan = np.full(BINS, np.nan)
    return LayerIdentity(l, lay.W.copy(), lay.b.copy(), np.full((d, p + 1), np.inf), 1.0, float("inf"), (),
                         "unresolved", nan, nan.copy(), _curve(lay, act, s2), float(np.sqrt(s2)), s_se, kurt,
                         tuple(rows))


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


def _identify_layer(lay: _Layer, act: str, s_guess: float, t, depth: int, taps: bool,
                    trends: bool = True, memory: bool = True) -> LayerIdentity:
    """One layer's identification; ``trends``: whether a trend within the inputs' shots may be
    put into the map (see :func:`_within_trend`); ``memory``: whether the layer's memory is tested
    (:mod:`._memory`; False once it was taken out of the shots)."""
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    l = lay.layer
    transfer_cls = "activation_mismatch" if lay.hidden else "readout_nonlinearity"
    tt = None
    if t is not None:
        # the map is identified at t = 0, the start of the acquisition (reference §2's drift is
        # g = 1 + r t): a trend's time average is not a fixed error
        # the map's trends come from the inputs' mean times (a within-input trend would make the
        # model's mean move inside an input by a coefficient read off the means); they are fitted
        # only where those spread over a tenth of the campaign (not with an interleaved order,
        # where the within-input test below sees the trend)
        t = np.asarray(t, np.float64)
        tbar = t.mean(1, keepdims=True)
        tt = tbar if np.std(tbar) >= 0.1 else None
    k = p + 1 + (2 if tt is not None else 0)
    if n < k + RESOLVE_MARGIN:
        return _unresolved_layer(lay, act, s_guess, t, k)
    unc = _map_uncertainty(lay, act, s_guess)
    if unc > 1.0:
        return _unresolved_layer(lay, act, s_guess, t, k, f"its standard error is {unc:.3g} times the map itself: "
                                 f"the mean response barely depends on W at this noise level")
    mf = lay.mean_factor
    # noise level: two passes (the smoothing of sigma depends on it, only at second order)
    s2 = s_guess ** 2
    W0 = b0 = None
    # the within-cell regression (taps, a regressor varying within an input) spends p degrees
    # of freedom per neuron
    f2 = n * (r - 1) / max(n * (r - 1) - p, 1) if lay.A.shape[1] > 1 else 1.0

    def fit_at_level(lay, s2, W0, b0):
        """The map and the level in two passes, then the map at the level found."""
        for _ in range(2):
            W_eff, b_eff, drift, z, m, g, var, X, E = _fit_map(lay, act, s2, tt, W0=W0, b0=b0)
            W0, b0 = W_eff, b_eff
            obs = _cell_var(_within(E, g, lay.A), lay.res_var) * f2
            vu = _unit_var(lay, W_eff)
            s2 = _level(lambda v: float(np.sum(_mean_model(lay, act, W_eff, b_eff, v, vu, tt, drift)[3].mean(1))),
                        float(np.sum(obs)), s2)
        return _fit_map(lay, act, s2, tt, W0=W0, b0=b0), s2, W0, b0

    (W_eff, b_eff, drift, z, m, g, var, X, E), s2, W0, b0 = fit_at_level(lay, s2, W0, b0)
    extra_rows = []
    # ---- issue 48 hook: a gain wandering over the campaign, a map drifting (lab/_time.py), tested
    # beyond the straight lines read below; a named one is put into the map as a known term of the
    # pre-activation, like those lines, so the map is read at t = 0
    E_slow, slow = None, None
    if t is not None:
        slow = _time.slow_terms(lay, E, g, X, t, l, _row, _within)
        extra_rows.extend(slow.rows)
        if slow.offset is not None:
            E_slow = _within(E, g, lay.A)
            lay = dataclasses.replace(lay, offset=slow.offset)
            (W_eff, b_eff, drift, z, m, g, var, X, E), s2, W0, b0 = fit_at_level(lay, s2, W0, b0)
    # ---- issue 48 hook: memory (lab/_memory.py), read on the residuals beyond those slow terms; a
    # memory that is named is taken out of the shots and the layer read again, so its mean shift
    # is not read as the map's
    if memory and t is not None:
        lag = _memory.lag_test(l, _within(E, g, lay.A), lay.Y, t, _row, g, lay.A)
        if lag.p < _memory.UNDO_P:
            inner = _identify_layer(dataclasses.replace(lay, Y=_memory.undo(lay.Y, lag), offset=None), act, s_guess,
                                    t, depth, taps, trends, memory=False)
            return dataclasses.replace(inner, rows=inner.rows + (lag.row,))
        extra_rows.append(lag.row)
    elif memory:
        extra_rows.append(_memory.lag_test(l, E, lay.Y, None, _row).row)
    E_time = E_slow  # the time tests of the noise read the residuals without the terms put in
    # (the residuals with W_eff's error along each shot's own input removed, as the time tests read them)
    Ew = _within(E, g, lay.A) if tt is None and t is not None else None
    within = _within_trend(lay, Ew, g, t, _cell_var(Ew, lay.res_var)) if Ew is not None and trends else None
    trend_kind = None
    if within is not None:
        offset, trend_kind, trend_se = within
        # a trend within the inputs' shots: the map is read at t = 0 with it in place (with an
        # interleaved acquisition its time average is the same shift -- or gain -- of every
        # input's z: a bias drift was read as a shifted transfer and named activation_mismatch),
        # and the noise level without it; the time tests read the residuals with it
        E_time = Ew if E_time is None else E_time
        lay = dataclasses.replace(lay, offset=offset if lay.offset is None else lay.offset + offset)
        (W_eff, b_eff, drift, z, m, g, var, X, E), s2, W0, b0 = fit_at_level(lay, s2, W0, b0)
        Ew = None
    E = _within(E, g, lay.A) if Ew is None else Ew  # (already made for the trend's test)
    obs = _cell_var(E, lay.res_var) * f2
    # the across-neuron covariance per input where the map's covariance or the shape test needs
    # it (d^2 floats per input: not for a wide layer, whose noise tests read a subset)
    Chat = _cell_cov(E) * f2 if (d <= WIDE or d * k <= FULL_COV_MAX) else None
    rows = []

    # ---- the mean map and its restrictions
    S, full = _covariance(X, Chat, obs, r / mf)
    if within is not None:
        # the map at t = 0 carries the trend's error times the inputs' mean time: on the biases
        # (additive, per neuron) or along W as a common gain (rank one)
        if trend_kind == "additive":
            if full:
                S[np.arange(d) * k + p, np.arange(d) * k + p] += trend_se ** 2
            else:
                S[np.arange(d), p, p] += trend_se ** 2
        else:
            v = np.zeros((d, k))
            v[:, :p] = lay.W
            if full:
                S += trend_se ** 2 * np.outer(v.ravel(), v.ravel())
            else:
                S += trend_se ** 2 * v[:, :, None] * v[:, None, :]
    if slow is not None and slow.cov is not None:  # issue 48 hook: the map drift's error (lab/_time.py)
        _time.add_cov(S, full, slow.cov, k)
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
    Sa = S[np.ix_(idx, idx)] if full else _Blocks(S[alive])
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
    # ---- the activation's shape: binned residual shared by the neurons, beyond each affine map
    ebar = E.mean(1)
    zz = z[:, :, alive] if alive else z
    edges, H = _bin_shares(zz, z)  # H: (n, d, B)
    Bx = np.linalg.inv(_gram(X) + 1e-12 * np.eye(k))
    Xn = X.transpose(1, 0, 2)  # (d, n, k), a view
    proj = np.matmul(Xn, Bx @ np.matmul(Xn.transpose(0, 2, 1), H.transpose(1, 0, 2))).transpose(1, 0, 2)  # (n, d, B)
    Ht = (H - proj)[:, alive]
    ea = ebar[:, alive]
    Sg = np.einsum("nib,ni->b", Ht, ea)
    if Chat is not None:
        CH = np.matmul(Chat[:, alive][:, :, alive] * (mf / r), Ht)  # (n, i, c)
        Vg = Ht.reshape(-1, Ht.shape[2]).T @ CH.reshape(-1, Ht.shape[2])
    else:  # a wide layer: the neurons' noise taken as uncorrelated here (correlated_noise tests that)
        Vg = np.einsum("ni,nib,nic->bc", obs[:, alive] * mf / r, Ht, Ht, optimize=True)
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
    gain, gain_se = 1.0, float("inf")
    choice = "general"
    p_time_det = 0.0
    rel = 0.0
    W_idx = (np.arange(da)[:, None] * k + np.arange(p)[None, :]).ravel()
    if da:
        fits = _gls_all(th, Sa, models)
        pfit = {name: _chi2(f[2], th.size - models[name].shape[1], nu)[0] for name, f in fits.items()}
        # the programmed map by a score test at it (no fitted map: a weakly identified neuron,
        # e.g. a saturated one, can wander far in W_eff, and a Wald test there rejected the
        # programmed map on 10 % of null files at layer 2 of 12-24-12-6 with taps)
        p_omni, z_omni = _score_omnibus(lay, act, s2, tt, Chat, obs, r / mf, alive, nu)
        # where both fit (biases near 0: a gain on W is a gain on z), a hidden layer's is read as
        # its activation's slope, the output's as a gain on its weighted sum
        order = (("programmed", "transfer", "gain") if lay.hidden else ("programmed", "gain", "transfer")) \
            + ("bias", "gain+bias", "rows")
        for name in order:
            if (p_omni if name == "programmed" else pfit[name]) >= ALPHA:
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
        q_w = (float(np.einsum("ip,ipq,iq->", Wa, Sa.blocks[:, :p, :p], Wa)) if isinstance(Sa, _Blocks)
               else float(wv @ Sa[np.ix_(W_idx, W_idx)] @ wv))
        g_se_tot = float(np.sqrt(max(q_w, 0.0) / max(w2, 1e-300) ** 2
                                 + tau2 / max(w2, 1e-300)))
        rel = float(np.sqrt(np.mean(Eg ** 2)) / max(np.sqrt(np.mean(Wa ** 2)), 1e-300))
        if choice in ("gain+bias", "general"):
            gain = g_ols
        g_at = gain
        trend = ""
        se_use = gain_se if choice == "gain" else g_se_tot
        z_gain = (g_at - 1.0) / se_use if se_use > 0 else 0.0

        # when the residual has a shape of z shared by the neurons (the shape test rejects), the
        # map is tested again given that shape: a transfer that is not the programmed activation
        # moves the fitted map too (measured: weight_error led activation_mismatch on an
        # asymmetric modulator, a sin modulator and a square-law detector, the right class
        # listed second); the map's classes are no more significant than what remains
        p_shape_free = (_score_given_shape(lay, act, s2, tt, Chat, r / mf, alive, nu)
                        if ps < ALPHA and Chat is not None and da * k <= FULL_COV_MAX else None)

        if p_shape_free is not None:
            for rw in rows:
                if rw["test"] == "shape":
                    rw["evidence"] += (f"; given that shape the map is the programmed one (p = {p_shape_free:.2g})"
                                       if p_shape_free >= ALPHA else
                                       f"; the map deviates beyond that shape too (p = {p_shape_free:.2g})")

        def floor(pv):  # no class is more significant than the omnibus deviation from the programmed map
            return max(pv, p_omni, p_shape_free if p_shape_free is not None else 0.0)

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
            where, cls_r = ("detector", "readout_nonlinearity") if not lay.hidden else ("modulator", transfer_cls)
            text = ""
            if lay.hidden:
                q_det, q_mod, _, p_sh, p_tdet = _detector_or_modulator(lay, act, s2, obs, mf, alive, tt)
                if q_det < q_mod:
                    where, cls_r = "detector", "readout_nonlinearity"
                    _shape_given_detector(rows, p_sh)
                    p_time_det = p_tdet
                text = (f"; as a {where}'s it fits better: weighted squared residual {min(q_det, q_mod):.4g} "
                        f"against the {'modulator' if where == 'detector' else 'detector'}'s {max(q_det, q_mod):.4g} "
                        f"over {n} x {da} means")
            rows.append(_row(cls_r, "neuron_transfer", floor(pr), zr, float(np.sqrt(np.mean(gi ** 2))),
                             f"each neuron's z at layer {l} scaled and shifted on its own: gains "
                             f"{1 + gi.min():.3f}..{1 + gi.max():.3f} on (W, b) of its row, shifts rms "
                             f"{np.sqrt(np.mean(phi_r[da:2 * da] ** 2)):.3g} (a {where}'s gain and offset; fits, "
                             f"p = {pfit['rows']:.2g}{text})"))
        if choice == "general" and lay.hidden:
            # no restricted map of z fits: the neurons' own gains and offsets may act after the
            # activation (a detector, D of reference §2), which no map of z expresses
            q_det, q_mod, q_prog, p_sh, p_tdet = _detector_or_modulator(lay, act, s2, obs, mf, alive, tt)
            df_det = n * da - 2 * da
            if stats.chi2.sf(q_det, df_det) >= ALPHA:
                choice = "detector"
                _shape_given_detector(rows, p_sh)
                p_time_det = p_tdet
                p_lr = float(stats.chi2.sf(max(q_prog - q_det, 0.0), 2 * da))
                rows.append(_row("readout_nonlinearity", "neuron_transfer", floor(p_lr), _z_of_p(max(p_lr, 1e-300)),
                                 float(np.sqrt(max(q_prog - q_det, 0.0) / max(q_prog, 1e-300))),
                                 f"each neuron of layer {l} has its own gain and offset after the activation (a "
                                 f"detector's: g_i sigma(z) + o_i fits the per-input means, chi2 {q_det:.0f} on "
                                 f"{df_det} df, where no map of z does and a modulator's sigma(g_i z + o_i) leaves "
                                 f"{q_mod:.0f}; against the programmed map chi2 {q_prog - q_det:.0f} on {2 * da} df)"))
        if choice in ("bias", "gain+bias", "general"):
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
                dbs, Sb = th[b_idx], _sub(Sa, b_idx)
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
            qt = float(th[tr] @ _solve_psd(_sub(Sa, tr), th[tr]))
            pt, zt = _chi2(qt, tr.size, nu)
            if p_time_det > pt:  # a detector's layer: the trend read on the detector's residual
                pt, zt = p_time_det, _z_of_p(p_time_det) if p_time_det < 1.0 else 0.0
            # the same trend against the scatter of the inputs' own contributions: a misfit of the
            # mean that is no trend (a saturating readout's curve beyond the shape's bins) enters
            # the trend's estimate at random, and the noise's covariance alone does not count it
            # (layer 1 of a saturating 6-12-6-4 chip: a "trend" at p = 1e-65, none within the shots)
            p_rob = _robust_trend_p(X, ebar, alive, p, theta)
            robust = ""
            if p_rob > pt:
                pt, zt = p_rob, _z_of_p(p_rob) if p_rob < 1.0 else 0.0
                robust = f"; p = {p_rob:.2g} against the inputs' own scatter, which counts the mean's misfit"
            zc_ = th[tr] / np.sqrt(np.maximum((Sa.diag() if isinstance(Sa, _Blocks) else np.diag(Sa))[tr], 1e-300))
            wi = int(np.argmax(np.abs(zc_)))
            rows.append(_row("time_drift", "time_map", pt, zt, float(np.max(np.abs(th[tr]))),
                             f"the map at layer {l} moves over acquisition time: "
                             f"{'additive' if wi < da else 'gain'} trend {th[tr][wi]:+.3g} per unit t at "
                             f"{l}:{alive[wi % da]} (z = {zc_[wi]:.1f}{' against the noise alone' if robust else ''}; "
                             f"chi2 z = {zt:.1f} over the layer{robust})",
                             [alive[wi % da]]))

    curve = _curve(lay, act, s2)

    # ---- the noise
    sub = _subset(d)
    Chat_s = Chat[:, sub][:, :, sub] if Chat is not None else _cell_cov(E[:, :, sub]) * f2
    # the model's noise covariance at the map chosen, not at the unrestricted W_eff: W_eff's
    # error is one draw shared by every input, so W_eff C W_eff^T (no taps: C the hidden
    # layers' propagated noise) carried a bias the test over inputs could not average out
    # (correlated_noise on 12 % of null files without taps)
    W_n = (lay.W if choice in ("programmed", "bias", "detector") else gain * lay.W if choice in ("gain", "gain+bias")
           else W_eff)
    # a hidden layer's noise is bent by its activation at z: at the programmed map when the data
    # keep it, for the same reason -- W_eff's error spreads z, |W_eff|^2 ~ |W|^2 + its variance, and
    # the activation's variance at the spread z is smaller (at s = 1, W_eff's standard error 0.6 of
    # W on 120 inputs, layer 2's level read 1.26 and its kurtosis named noise_law on null files)
    at_programmed = lay.hidden and choice == "programmed"
    if (lay.Cin is not None or at_programmed) and W_n is not W_eff:
        # ... and so the noise variance and level: the unmeasured input noise reaches the layer
        # through W, and W_eff's error, larger along directions the inputs barely span, only adds
        # to W_eff C W_eff^T (no taps, a 3-neuron hidden layer upstream: the level read 0.033 at
        # s = 0.061, and the variance's input dependence was named on 4 % of null files at 0.01)
        vu_n = _unit_var(lay, W_n)
        W_m, b_m = (W_n, lay.b) if at_programmed else (W_eff, b_eff)
        if at_programmed:  # the residuals too: W_eff's error moves them within an input beyond its linear part
            E = lay.Y - _mean_model(lay, act, W_m, b_m, s2, vu_n, tt, drift, want_var=False)[1]
            obs = _cell_var(E, lay.res_var)
            Chat_s = _cell_cov(E[:, :, sub])
        s2 = _level(lambda v: float(np.sum(_mean_model(lay, act, W_m, b_m, v, vu_n, tt, drift)[3].mean(1))),
                    float(np.sum(obs)), s2)
        z_m, m_m, g_m, var = _mean_model(lay, act, W_m, b_m, s2, vu_n, tt, drift)
        if at_programmed:
            z, g = z_m, g_m
            E = lay.Y - m_m
            obs = _cell_var(E, lay.res_var)
            Chat_s = _cell_cov(E[:, :, sub])
    noise_rows, s_lvl, s_se, kurt = _noise_rows(lay, act, l, t, E, obs, Chat_s, sub, z, g, var, b_eff, s2,
                                                _unit_var(lay, W_n), _unit_cov(lay, W_n, sub), E_time)
    rows.extend(noise_rows)
    _time.attach_share(extra_rows, noise_rows)  # issue 48: the wander's share of the gain's variance
    if trend_kind == "gain":
        share = next((r_.get("share") for r_ in noise_rows if r_["test"] == "time_within"), None)
        if share is not None and share < TREND_SHARE:
            # the gain's trend carries little of its variance within the inputs' shots: the path of
            # a fluctuating gain (an AR(1) laser), whose straight line's value at t = 0 means
            # nothing -- the map is read without it (put in, it read a gain of 0.89 at t = 0)
            inner = _identify_layer(dataclasses.replace(lay, offset=None), act, s_guess, t, depth, taps, trends=False,
                                    memory=False)
            return dataclasses.replace(inner, rows=inner.rows + tuple(extra_rows))
    return LayerIdentity(l, W_eff, b_eff, se, gain, gain_se, tuple(dead), choice, zc, gam, curve,
                         s_lvl, s_se, kurt, tuple(rows) + tuple(extra_rows))


@dataclasses.dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`LayerIdentity` per identified layer.

    taps : whether each layer was identified on its own (taps) or only the output
    levels_row : the test of equal noise levels across layers (taps), or None
    output_candidates : without taps, each candidate mechanism put into the model and its lack
        of fit of the output's mean (:func:`~gift_theory.lab._explain_output.explain`), else ()
    """

    taps: bool
    depth: int
    layers: tuple
    levels_row: dict | None = None
    output_candidates: tuple = ()

    def rows(self) -> list[dict]:
        """Every test with its layer and Holm-adjusted p-value (``p_adj``) over classes x layers
        (fresh dicts: a caller may change them)."""
        return [dict(r_) for r_ in self._rows]

    @functools.cached_property
    def _rows(self) -> tuple:
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
        return tuple(out)

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


def _levels_row(out: list) -> dict | None:
    """The test of equal noise levels across the layers (taps), or None with fewer than two
    layers of one level. A layer whose noise variance changes with its signal (its
    input-dependence test rejects at ALPHA, Bonferroni over every test, so no more often than a
    class is named) has no one level: its mean level rises with its signals, and the layers'
    levels differ though each one's noise at zero signal is the chip's (weighted-sum noise
    s (1 + beta |u|) in the hidden layers was named noise_level first: levels 0.051-0.058 there
    against the output's 0.041, the chip's s); the levels are compared over the others."""
    m_tests = 1 + sum(r_["class"] != "_omnibus" for li in out for r_ in li.rows)
    lv = [li for li in out if not any(r_["class"] == "input_dependent_noise" and r_["p"] * m_tests < ALPHA
                                      for r_ in li.rows)]
    if len(lv) < 2:
        return None
    x = np.array([np.log(li.s ** 2) for li in lv])
    se = np.array([2 * li.s_se / max(li.s, 1e-300) for li in lv])
    w = 1.0 / np.maximum(se ** 2, 1e-300)
    xb = float(np.sum(w * x) / np.sum(w))
    # levels within LEVEL_TOLERANCE of each other (in log s^2) are one level: the layers' unit
    # variances are modelled to about 1 % at 16 shots per input (measured on null files)
    q = float(np.sum(w * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) ** 2))
    p, z = _chi2(q, len(lv) - 1)
    zl = np.sign(x - xb) * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) * np.sqrt(w)
    bad = [li.layer for li, zz in zip(lv, zl) if abs(zz) > 3.0]
    worst = int(np.argmax(np.abs(zl)))
    levels = _row("noise_level", "levels", p, z, float(lv[worst].s),
                  "noise levels per layer " + ", ".join(f"{li.s:.3g}" for li in lv)
                  + f" (layer {lv[worst].layer} stands out, z = {zl[worst]:.1f})")
    levels["layer"] = lv[worst].layer
    levels["layers"] = bad or [lv[worst].layer]
    if len(lv) < len(out):
        levels["evidence"] += (" (layer(s) " + ", ".join(str(li.layer) for li in out if li not in lv)
                               + " left out: their noise variance changes with the signal)")
    return levels


def _identify(meas: Measurement, s: float | None) -> Identification:
    act = meas.activation if meas.activation in _ACT else "tanh"
    if s is None:
        Y0 = np.asarray(meas.layers()[0], np.float64)
        s = float(np.sqrt(np.mean(np.var(Y0, axis=1, ddof=1)) / 2.0)) if meas.r > 1 else 0.05
        # relative to the data, not a fixed floor: a constant layer still gets a level > 0
        s = max(s, 1e-7 * float(np.sqrt(np.mean(Y0 ** 2))), np.finfo(np.float32).tiny)
    lays = _layers(meas, s)
    out = [_identify_layer(lay, act, s, meas.t, meas.arch.depth, meas.has_taps) for lay in lays]
    if not meas.has_taps and meas.arch.depth > 1:
        # the output's regressor and noise are propagated at the level s: again at the level found,
        # to its fixed point (the regressor's mean moves with s at second order, and at 160 x 48
        # shots a start 5 % off rejected the programmed map on null files)
        for _ in range(6):
            if abs(out[-1].s / s - 1.0) < 1e-3:
                break
            s = out[-1].s
            out = [_identify_layer(lay, act, s, meas.t, meas.arch.depth, False) for lay in _layers(meas, s)]
    # a layer on a lattice (a quantizing readout): a finding of its own
    ids, Ys = meas.layer_ids(), meas.layers()
    out = [dataclasses.replace(li, rows=li.rows + tuple(rw for rw in [lattice_row(Ys[ids.index(li.layer)], li.layer)]
                                                        if rw is not None)) for li in out]
    cands = ()
    if not meas.has_taps and meas.arch.depth > 1:
        from ._explain_output import explain
        cands = tuple(explain(meas, out[-1].s))
    levels = _levels_row(out) if meas.has_taps and len(out) > 1 else None
    return Identification(meas.has_taps, meas.arch.depth, tuple(out), levels, cands)


#: what the output alone cannot separate (no taps); docs/identification.md has the full table
CANNOT_SEPARATE_WITHOUT_TAPS = (
    "which layer a deviation of the mean map, the gain or the biases sits in (all fold into the output's)",
    "an activation's shape from a readout's transfer",
    "the noise level of one layer from another's (one level is seen)",
)
