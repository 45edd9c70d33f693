"""What each layer's identification reads: the regressor and shots of a layer (taps), or the
output with the hidden layers' noise propagated to it by Monte Carlo (no taps); the model's
mean, slope and noise variance per shot; the noise level's fixed point."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..._arch import NUMPY_ACTIVATIONS as _ACT
from ..._measurement import Measurement
from .._discrete import resolution_var
from .._smoothing import smoothed
from ._stats import _shots_law

#: bins of z of the activation's shape
BINS = 8


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
    #: (P, se) or None: the shots had a memory taken out (:func:`.._memory.undo`), alpha read with
    #: standard error ``se``; P (n, d) per input and neuron the mean of its shots' previous
    #: acquisitions. The means moved by -alpha P, so alpha's error is an error of the map (acquired
    #: input by input, P is about the mean itself: a gain) that its covariance and tests carry
    memory: tuple | None = None

    @property
    def mean_factor(self) -> float:
        """How much a per-input mean residual's variance exceeds its shots' (Monte Carlo regressor)."""
        return 1.0 + (self.Y.shape[1] / self.draws if self.draws else 0.0)


def _propagate(meas: Measurement, s: float, kept: dict | None = None):
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
    ``kept``: a dict in which the standard normal draws are kept for the next call on the same
    measurement (:class:`_Kept`). Returns (mean, cov, draws, law or None, basis or None)."""
    n, p = np.shape(meas.x)
    macs = sum(np.size(W) for W, _ in meas.params[:-1]) + p
    M = int(max(MC_MIN_DRAWS, min(MC_DRAWS, MC_FLOPS / max(n * macs, 1))))
    out = _propagate_draws(meas, s, M, M, kept)
    mean, cov = out[0], out[1]
    spread = float(np.mean(np.var(mean, axis=0)))
    err = s * s * float(np.mean(np.einsum("nii->ni", cov))) / M  # the per-input mean's variance from the draws
    if n > 1 and err > MC_ATTENUATION * spread:
        cap = int(max(M, MC_FLOPS_MAX / max(n * macs, 1)))
        want = M * err / (MC_ATTENUATION * max(spread, np.finfo(np.float64).tiny))
        M2 = int(min(cap, M * 2 ** int(np.ceil(np.log2(want / M)))))  # powers of 2: the same draws across nearby s
        if M2 > M:
            out = _propagate_draws(meas, s, M2, M, kept)
    return out


#: the propagation's standard normal draws are kept between the calls of one identification (the
#: noise level's fixed point propagates again at each level, with the same draws) up to this many
#: floats per draw count, else drawn again (the same numbers either way)
KEEP_PROPAGATION_DRAWS = 2e7


class _Kept:
    """A generator's ``standard_normal`` whose draws are kept in ``store`` (a list) and given again,
    in the same order, to the next propagation that reads the same list: the numbers of a fresh
    generator of the same seed, without drawing them twice."""

    def __init__(self, rng, store: list):
        self.rng, self.store, self.i = rng, store, 0
        self.replaying = bool(store)

    def standard_normal(self, shape):
        if self.i < len(self.store):
            out = self.store[self.i]
            if out.shape != tuple(shape):
                raise RuntimeError(f"kept draws of shape {out.shape} read as {tuple(shape)} (another measurement?)")
        else:
            if self.replaying:  # the generator is still at its start: a fresh draw here would repeat the kept ones
                raise RuntimeError(f"the {len(self.store)} kept draws ran out (another measurement?)")
            out = self.rng.standard_normal(shape)
            self.store.append(out)
        self.i += 1
        return out


def _propagate_draws(meas: Measurement, s: float, M: int, M_law: int, kept: dict | None = None):
    """:func:`_propagate` with M draws per input (the law from the first ``M_law`` of them); the
    draws kept in ``kept`` (keyed by the draw counts) when it is given and they fit
    :data:`KEEP_PROPAGATION_DRAWS`."""
    act = _ACT[meas.activation if meas.activation in _ACT else "tanh"][0]
    x = np.asarray(meas.x, np.float64)
    params = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in meas.params[:-1]]
    n, p = x.shape
    d = params[-1][0].shape[0]
    W_L = np.asarray(meas.params[-1][0], np.float64)
    r = meas.r
    G = min(M, M_law) // r if r >= 5 else 0
    size = x.shape[0] * (M * (p + 2 * sum(W.shape[0] for W, _ in params)) + G * r * W_L.shape[0])
    rng, rng_law = np.random.default_rng(20261127), np.random.default_rng(20261128)
    if kept is not None and size <= KEEP_PROPAGATION_DRAWS:
        stores = kept.setdefault((M, M_law), ([], []))
        rng, rng_law = _Kept(rng, stores[0]), _Kept(rng_law, stores[1])
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


def layer_inputs(meas: Measurement, s: float, kept: dict | None = None) -> list:
    """What each identified layer reads (:class:`_Layer`): every layer (taps) or the output (no taps;
    ``kept``: see :func:`_propagate`)."""
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
    m, C, M, law, basis = _propagate(meas, s, kept)
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


def unit_variance(Cin, W_eff, n: int):
    """The unit (per s^2) variance of each neuron's pre-activation noise (n, d): its own noise (1)
    plus the unmeasured input noise of unit covariance ``Cin`` -- None (none), (p, p) or (n, p, p)
    per input -- through the weights ``W_eff`` (d, p).

    Parameters
    ----------
    Cin : None or ndarray, shape (p, p) or (n, p, p)
    W_eff : ndarray, shape (d, p)
    n : the number of inputs

    Returns
    -------
    ndarray, shape (n, d)
    """
    d = W_eff.shape[0]
    if Cin is None:
        return np.ones((n, d))
    if Cin.ndim == 2:
        return np.broadcast_to(np.sum((W_eff @ Cin) * W_eff, axis=-1) + 1.0, (n, d))
    return np.sum(np.matmul(W_eff, Cin) * W_eff, axis=-1) + 1.0


def _unit_var(lay: _Layer, W_eff):
    """The diagonal of :func:`_unit_cov` (n, d): what the means need."""
    return unit_variance(lay.Cin, W_eff, lay.Y.shape[0])


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


def _subset(d: int) -> np.ndarray:
    """The neurons whose covariance is read: all, or :data:`WIDE` evenly spaced."""
    return np.arange(d) if d <= WIDE else np.unique(np.linspace(0, d - 1, WIDE).round().astype(int))


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
