"""Without taps: which single mechanism, put into the model, explains the output's mean.

Without taps only the output is measured, and every layer's deviation folds into the output's
mean map: a dead neuron in layer 2, a transfer that is not tanh, a detector's gain and offset
all show as ``W_eff - W`` at the output, and the layer-wise tests (:mod:`.identification`) read them
as a weight error there. This module asks the converse question, at the network level: for each
candidate mechanism H -- a class of reference §6 at a layer, with its own few parameters --
does the model *with H in it* reproduce the per-input mean of every output neuron?

* The output's mean and its derivatives in each candidate's parameters come from one Monte
  Carlo propagation through the programmed model (reference §1, awgn at the identified level s,
  the standard normal draws fixed), the output's sensitivity to each hidden layer's activation
  carried back draw by draw (``G_{L-1} = W_L``, ``G_l = G_{l+1} diag(sigma'(z_{l+1})) W_{l+1}``);
  the noise level's column by a central difference on the same draws.
* Each candidate is fitted by weighted least squares of the per-input mean residuals on its
  columns (s a nuisance column of every candidate); those closest to passing are then fitted
  through the model itself by Levenberg-Marquardt from the programmed model, the columns
  recomputed at each accepted point on the same draws (a dead neuron is not a small
  deformation, and the deformations of several layers interact).
* Its lack of fit is the sum over inputs x output neurons of the squared standardised
  residuals (each cell's variance: its shots' over r plus the model's Monte Carlo error), set
  against what noise alone leaves, ``n d kappa - k`` with ``kappa = (r - 1) / (r - 3)`` (a mean
  standardised by its own r-shot variance), in units of its null spread (per input
  ``2 sum_ij R_ij^2`` kappa^2, R the correlation of the output's neurons within a shot: neurons
  of one input share noise). A candidate *explains the output's mean* when that z is below
  :data:`Z_PASS`.

The candidates (``k`` parameters each, s included): a gain on W_l, or one per layer
(``gain_error``); shifts of b_l, or of every layer's (``bias_offset``); a deformation of layer
l's transfer shared by its neurons (Legendre polynomials of degree 1 to :data:`DEGREE` in the
scaled pre-activation, and a constant), one shape for every hidden layer, or one per hidden layer
(``activation_mismatch``); one hidden neuron's own gain and offset (``activation_mismatch``: a
dead or stuck neuron; each neuron its own candidate); the output's transfer, a curve shared by
its neurons (with a constant) or each output neuron's gain and offset, and every neuron's detector gain and offset
on every layer (``readout_nonlinearity``); a layer's general weight error (``weight_error``).
A candidate with more than :data:`MAX_SHARE` of the data's cells as parameters is not fitted:
it would explain anything.

:func:`explain` returns the candidates with their lack of fit; :func:`order_map_classes` puts,
among the mechanism list's map classes, the classes whose candidates explain the mean first
(by an information criterion) and those none of whose candidates does after them.
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
from scipy import stats

from .._arch import NUMPY_ACTIVATIONS
from .._measurement import Measurement

#: Legendre degree of a shared transfer's deformation
DEGREE = 7
#: a candidate explains the output's mean when its lack-of-fit z is below this (one-sided 1 %)
Z_PASS = 2.326
#: Monte Carlo draws per input (the draws' error is part of each cell's variance)
DRAWS = 256
#: a candidate with more parameters than this share of the data's cells is not fitted
MAX_SHARE = 0.1
#: a layer's general weight error is a candidate only with at most this many derivative
#: columns x output neurons (memory: n times that many floats)
WEIGHT_COLS = 4096
#: candidates refined by Levenberg-Marquardt trials (those closest to passing, lack of fit z below REFINE_Z)
REFINE = 4
REFINE_Z = 40.0
#: the noise levels (times the identified one) at which the output's curve is fitted again when
#: it is the closest candidate and fails
LEVELS = (0.5, 1.5, 2.0, 3.0, 4.0)
#: the output's curve candidate
CURVE = "the output's transfer (a curve shared by its neurons)"
#: the shape polynomials' range: this many times the largest |z| of the first propagation
SCALE_HEADROOM = 1.5
LM_TRIALS = 8
#: the draws of the propagation are kept in memory up to this many floats (else drawn again)
KEEP_DRAWS = 2e7
#: print each refinement trial to stderr (a study's trace; off by default)
TRACE = False
#: the map classes this module orders (noise classes are not a question of the mean)
MAP_CLASSES = ("gain_error", "bias_offset", "activation_mismatch", "readout_nonlinearity", "weight_error")

#: the activations whose output the candidates are put into (another reads as tanh, as it always has)
_EXPLAINED = ("tanh", "sigmoid", "identity")
_ACT = {name: NUMPY_ACTIVATIONS[name] for name in _EXPLAINED}


@dataclasses.dataclass(frozen=True)
class OutputCandidate:
    """One mechanism put into the model: its class, what it is, its layers, its parameters
    (``k``, the noise level included), its lack of fit (``q``, its ``z`` and one-sided ``p``)."""

    mechanism: str
    name: str
    layers: tuple
    k: int
    q: float
    z: float
    p: float
    #: the Bayesian information criterion q + k log(cells): how candidates that explain the mean
    #: are ordered (a single neuron's 3 parameters against a readout's 7 is no reason to prefer
    #: it when its misfit is larger by 2 sd, and there are as many neuron candidates as neurons)
    bic: float = 0.0

    @property
    def explains(self) -> bool:
        return self.z < Z_PASS

    def to_dict(self) -> dict:
        return {"mechanism": self.mechanism, "candidate": self.name, "layers": list(self.layers),
                "parameters": self.k, "lack_of_fit_z": self.z, "p_value": self.p,
                "explains": bool(self.explains)}


def _legendre(z, scale, degree=None):
    """Legendre polynomials of degree 1..DEGREE of z / scale (clipped to [-1, 1]), stacked on a
    trailing axis (Bonnet's recursion: numpy's legvander is 5 times slower on these arrays)."""
    degree = DEGREE if degree is None else degree
    u = np.clip(z / scale, -1.0, 1.0)
    out = np.empty(u.shape + (degree,))
    prev, cur = np.ones_like(u), u
    out[..., 0] = u
    for k in range(1, degree):
        prev, cur = cur, ((2 * k + 1) * u * cur - k * prev) / (k + 1)
        out[..., k] = cur
    return out


def _legendre_series(z, scale, coef):
    """sum_j coef[j] P_j(z / scale) (clipped), j from 0, by the recursion: no stacked array of
    every degree (memory-bound at the sizes here)."""
    u = np.clip(z / scale, -1.0, 1.0)
    acc = np.full(u.shape, float(coef[0]))
    prev, cur = np.ones_like(u), u
    for k in range(1, len(coef)):
        if coef[k] != 0.0:
            acc += coef[k] * cur
        prev, cur = cur, ((2 * k + 1) * u * cur - k * prev) / (k + 1)
    return acc


def _legendre_slope(z, scale, c):
    """d/dz of sum_k c_k P_k(z / scale), k = 1..DEGREE (0 where z / scale is clipped):
    P_k' = sum over j < k, j + k odd, of (2 j + 1) P_j."""
    D = np.zeros(DEGREE)  # coefficients of sum_k c_k P_k' on P_0 .. P_{DEGREE-1}
    for k in range(1, DEGREE + 1):
        for j in range(k - 1, -1, -2):
            D[j] += c[k - 1] * (2 * j + 1)
    return np.where(np.abs(z) <= scale, _legendre_series(z, scale, D), 0.0) / scale


class _Draws:
    """The standard normal draws of the propagation, per chunk of inputs: the same numbers at
    every call (each chunk its own stream), kept in memory up to :data:`KEEP_DRAWS` floats (the
    draws were 3/4 of a propagation's time), else drawn again."""

    def __init__(self, seed, n, sizes, chunk):
        self.seed, self.n, self.sizes, self.chunk = seed, n, sizes, chunk
        self.keep = n * DRAWS * sum(sizes) <= KEEP_DRAWS
        self.cache = {}

    def __call__(self, c0):
        if c0 in self.cache:
            return self.cache[c0]
        c = min(self.chunk, self.n - c0)
        rng = np.random.default_rng([self.seed, c0])
        out = [rng.standard_normal((c, DRAWS, k)) for k in self.sizes]
        if self.keep:
            self.cache[c0] = out
        return out


def _chunk(x, params):
    o = params[-1][0].shape[0]
    widest = max([x.shape[1]] + [W.shape[0] for W, _ in params])
    return max(1, int(3e6 // (DRAWS * o * widest)))


def _draws_for(x, params, seed):
    """The draws of a propagation: the input's noise, then per layer its weighted sum's and (hidden
    layers) its activation's."""
    sizes = [x.shape[1]]
    for l, (W, _) in enumerate(params, start=1):
        sizes += [W.shape[0]] * (2 if l < len(params) else 1)
    return _Draws(seed, x.shape[0], sizes, _chunk(x, params))


def _propagate(x, params, act, s, seed, scales=None, deform=None, columns=False, want=None):
    """Per input the output's mean (n, o) and its Monte Carlo variance (n, o) through the model
    with ``deform`` ({(kind, layer): values}) in place (``seed``: an int or the :class:`_Draws`
    to use); with ``columns``, also the derivative
    columns {(kind, layer): (n, o, k)} at that point (the weights' only those in ``want``,
    when given), and the scales of the shape polynomials.

    A hidden layer's transfer with its deformation is ``(sigma(z) + P(z) c)(1 + alpha) + beta``
    (P: :func:`_legendre`), its weights ``W (1 + g) + dW``, its biases ``b + db``; the output is
    ``z_L + P(z_L) c_L`` with its rows' gains ``(1 + alpha_L)``."""
    f, _ = _ACT[act]
    deform = deform or {}
    draws = seed if isinstance(seed, _Draws) else _draws_for(x, params, seed)
    L = len(params)
    n, p = x.shape
    o = params[-1][0].shape[0]
    chunk = draws.chunk
    mean, vmc = np.empty((n, o)), np.empty((n, o))
    cols = {}
    s = s * (1.0 + float(deform.get(("s", 0), 0.0)))
    for c0 in range(0, n, chunk):
        xc = x[c0:c0 + chunk]
        c = xc.shape[0]
        normals = iter(draws(c0))
        a = xc[:, None, :] + s * next(normals)
        rec = []
        for l, (W, b) in enumerate(params, start=1):
            Wd = W * (1.0 + deform.get(("gain", l), 0.0))
            if ("weight", l) in deform:
                Wd = Wd + deform[("weight", l)].reshape(W.shape)
            u_raw = a @ Wd.T  # before the output rows' gains
            alpha = deform.get(("alpha", l), 0.0)
            u = u_raw * (1.0 + alpha) if l == L else u_raw
            z = u + b + deform.get(("bias", l), 0.0) + s * next(normals)
            layer = {"z": z}
            if columns:  # what the derivative columns read (the programmed sum: one more product)
                layer.update({"a_in": a, "u_prog": a @ W.T, "u_raw": u_raw, "Wd": Wd * (1.0 + alpha)[:, None]
                              if l == L and np.ndim(alpha) else Wd, "alpha": alpha})
            rec.append(layer)
            if l == L:
                break
            if scales is None and ("shape", l) in deform:
                raise ValueError("a shape deformation needs the scales of the first propagation")
            base = f(z)
            if ("shape", l) in deform:
                base = base + _legendre_series(z, scales[l - 1], np.r_[0.0, deform[("shape", l)]])
            fz = base * (1.0 + alpha) + deform.get(("beta", l), 0.0)
            layer["base"] = base
            a = fz + s * next(normals)
        y0 = z
        if scales is None:  # the shape polynomials' scale per layer: set on the first chunk
            # (half again the largest |z| of the first chunk: a scale at a high quantile clipped
            # the largest cells' draws, and a square law's y^2 was not a polynomial there)
            scales = [SCALE_HEADROOM * float(np.max(np.abs(r_["z"]))) or 1.0 for r_ in rec]
        y = y0 + _legendre_series(y0, scales[L - 1], np.r_[0.0, deform[("shape", L)]]) if ("shape", L) in deform else y0
        y = y + deform.get(("post", L), 0.0)
        mean[c0:c0 + chunk] = y.mean(1)
        vmc[c0:c0 + chunk] = y.var(1, ddof=1)
        if columns:
            _accumulate(cols, c0, c, n, params, act, rec, y0, scales, deform, want)
    return mean, vmc, cols, scales


def _accumulate(cols, c0, c, n, params, act, rec, y0, scales, deform, want):
    """The derivative columns of one chunk of inputs at the deformed point, written into
    ``cols``: the output's sensitivity to each hidden layer's activation carried back draw by
    draw, ``G_{L-1} = diag(r) W_L``, ``G_{l-1} = G_l diag(slope_l) W_l`` (r: the readout
    curve's slope, slope_l: layer l's deformed transfer's)."""
    L = len(params)
    o = params[-1][0].shape[0]
    M = y0.shape[1]

    def put(key, val):
        if key not in cols:
            cols[key] = np.empty((n,) + val.shape[1:])
        cols[key][c0:c0 + c] = val

    def wanted(key):
        return want is None or key in want

    out = rec[-1]
    ro = (1.0 + _legendre_slope(y0, scales[L - 1], deform[("shape", L)])) if ("shape", L) in deform else np.ones_like(y0)
    eye = np.eye(o)
    if wanted(("gain", L)):
        put(("gain", L), (ro * out["u_prog"] * (1.0 + out["alpha"])).mean(1)[:, :, None])
    if wanted(("bias", L)):
        put(("bias", L), ro.mean(1)[:, :, None] * eye[None])
    if wanted(("shape", L)):
        put(("shape", L), _legendre(y0, scales[L - 1]).mean(1))
    if wanted(("alpha", L)):
        put(("alpha", L), (ro * out["u_raw"]).mean(1)[:, :, None] * eye[None])
    a_last = out["a_in"]
    if o * o * a_last.shape[2] <= WEIGHT_COLS and wanted(("weight", L)):
        g = np.matmul((ro * (1.0 + out["alpha"])).transpose(0, 2, 1), a_last) / M  # (c, o, d_{L-1})
        put(("weight", L), (g[:, :, None, :] * eye[None, :, :, None]).reshape(c, o, -1))
    G = ro[:, :, :, None] * out["Wd"]  # d y / d a_{L-1}
    deepest = min([l for kind, l in want if kind != "s"], default=1) if want is not None else 1
    for l in range(L - 1, max(deepest, 1) - 1, -1):
        lay = rec[l - 1]
        z, base, a_in = lay["z"], lay["base"], lay["a_in"]
        alpha = lay["alpha"]
        slope = _slope(act, z)
        if ("shape", l) in deform:
            slope = slope + _legendre_slope(z, scales[l - 1], deform[("shape", l)])
        slope = slope * (1.0 + alpha)
        d = z.shape[2]
        Gd = G * slope[:, :, None, :]  # d y / d z_l
        if wanted(("bias", l)):
            put(("bias", l), Gd.mean(1))
        if wanted(("gain", l)):
            put(("gain", l), (Gd * lay["u_prog"][:, :, None, :]).sum(3).mean(1)[:, :, None])
        if wanted(("alpha", l)):
            put(("alpha", l), (G * base[:, :, None, :]).mean(1))
        if wanted(("beta", l)):
            put(("beta", l), G.mean(1))
        if wanted(("shape", l)):
            # sum over draws and neurons of G (1 + alpha) P(z): one batched matmul per input
            Ga = (G * (1.0 + alpha)).transpose(0, 2, 1, 3).reshape(c, o, M * d)
            u = np.clip(z / scales[l - 1], -1.0, 1.0).reshape(c, M * d, 1)
            col = np.empty((c, o, DEGREE))
            prev, cur = np.ones_like(u), u
            for k in range(DEGREE):  # P_{k+1}, one degree at a time (see _legendre_series)
                col[:, :, k] = np.matmul(Ga, cur)[:, :, 0]
                prev, cur = cur, ((2 * k + 3) * u * cur - (k + 1) * prev) / (k + 2)
            put(("shape", l), col / M)
        if o * d * a_in.shape[2] <= WEIGHT_COLS and wanted(("weight", l)):
            Gt = Gd.transpose(0, 2, 3, 1).reshape(c, o * d, M)
            put(("weight", l), np.matmul(Gt, a_in).reshape(c, o, -1) / M)
        if l > 1:
            G = np.matmul(Gd, rec[l - 1]["Wd"])  # d y / d a_{l-1}


def _slope(act, z):
    f, df = _ACT[act]
    return df(z, f(z))


@dataclasses.dataclass
class _Spec:
    mechanism: str
    name: str
    layers: tuple
    blocks: list  # [(kind, layer, index or None)]: index picks one neuron's column


def _specs(L: int, cols: dict) -> list:
    hidden = list(range(1, L))
    every = tuple(range(1, L + 1))
    out = [_Spec("none", "programmed", (), [])]
    for l in every:
        out.append(_Spec("gain_error", f"a gain on W{l}", (l,), [("gain", l, None)]))
    out.append(_Spec("gain_error", "a gain on every layer", every, [("gain", l, None) for l in every]))
    for l in every:
        out.append(_Spec("bias_offset", f"bias shifts at layer {l}", (l,), [("bias", l, None)]))
    out.append(_Spec("bias_offset", "bias shifts at every layer", every, [("bias", l, None) for l in every]))
    # a shape is its polynomial and a constant, both shared by the layer's neurons (P_0 is not in
    # the polynomial: a square-law detector's y^2 = (2/3) c^2 P_2(y / c) + c^2 / 3 needs it)
    for l in hidden:
        out.append(_Spec("activation_mismatch", f"layer {l}'s transfer (a shape shared by its neurons)", (l,),
                         [("shape", l, None), ("const", l, None)]))
    if len(hidden) > 1:
        out.append(_Spec("activation_mismatch", "every hidden transfer (one shape)", tuple(hidden),
                         [("shape*", 0, None)] + [("const", l, None) for l in hidden]))
        out.append(_Spec("activation_mismatch", "every hidden transfer (a shape per layer)", tuple(hidden),
                         [b for l in hidden for b in (("shape", l, None), ("const", l, None))]))
    for l in hidden:
        for j in range(cols[("alpha", l)].shape[2]):
            out.append(_Spec("activation_mismatch", f"neuron {l}:{j + 1}'s own gain and offset (dead or stuck)",
                             (l,), [("alpha", l, j), ("beta", l, j)]))
    out.append(_Spec("readout_nonlinearity", CURVE, (L,),
                     [("shape", L, None), ("const", L, None)]))
    out.append(_Spec("readout_nonlinearity", "each output neuron's gain and offset", (L,),
                     [("alpha", L, None), ("bias", L, None)]))
    out.append(_Spec("readout_nonlinearity", "every neuron's detector gain and offset", every,
                     [("alpha", l, None) for l in every] + [("beta", l, None) for l in hidden] + [("bias", L, None)]))
    for l in every:
        if ("weight", l) in cols:
            out.append(_Spec("weight_error", f"a general weight error in W{l}", (l,), [("weight", l, None), ("bias", l, None)]))
    return out


def _block(cols, kind, l, j, hidden):
    if kind == "shape*":
        return sum(cols[("shape", h)] for h in hidden)
    if kind == "const":  # one offset shared by the layer's neurons: the sum of their own offsets' columns
        if l not in hidden:  # the output's: added after its curve, so its column is 1 at every point
            n_, o_ = cols[("bias", l)].shape[:2] if ("bias", l) in cols else cols[("shape", l)].shape[:2]
            return np.ones((n_, o_, 1))
        return cols[("beta", l)].sum(2, keepdims=True)
    v = cols[(kind, l)]
    return v[:, :, j:j + 1] if j is not None else v


def _deform(spec: _Spec, theta, cols, hidden, o) -> dict:
    """The deformation {(kind, layer): values} of ``theta`` (s first, then the blocks)."""
    out = {("s", 0): float(theta[0])}
    i = 1
    for kind, l, j in spec.blocks:
        k = _block(cols, kind, l, j, hidden).shape[2]
        v = theta[i:i + k]
        i += k
        if kind == "shape*":
            for h in hidden:
                out[("shape", h)] = out.get(("shape", h), 0.0) + v
            continue
        if kind == "const":
            if l not in hidden:  # the output's constant, after its curve (not a shift of z_L, which the
                # curve would bend: with a square law's large coefficients the model left z = 255080
                # where the linear fit was z = 2)
                out[("post", l)] = out.get(("post", l), 0.0) + float(v[0])
                continue
            key = ("beta", l)
            out[key] = out.get(key, 0.0) + np.full(cols[key].shape[2], float(v[0]))
            continue
        if j is not None:
            full = np.zeros(cols[(kind, l)].shape[2])
            full[j] = v[0]
            v = full
        if kind == "gain":
            v = float(v[0])
        out[(kind, l)] = out.get((kind, l), 0.0) + v
    return out


def _null_spread(Y, kappa):
    """sd of the lack-of-fit sum under the null: per input 2 sum_ij R_ij^2 kappa^2 (R the
    within-shot correlation of the output's neurons, its squares' bias 1/(r-1) removed off the
    diagonal)."""
    n, r, o = Y.shape
    C = Y - Y.mean(1, keepdims=True)
    S = np.einsum("nki,nkj->nij", C, C) / max(r - 1, 1)
    sd = np.sqrt(np.maximum(np.einsum("nii->ni", S), 1e-300))
    R2 = (S / sd[:, :, None] / sd[:, None, :]) ** 2
    off = np.maximum(R2 - 1.0 / max(r - 1, 1), 0.0)
    tr = o + (off.sum((1, 2)) - np.einsum("nii->n", off))
    return float(np.sqrt(2.0 * kappa ** 2 * tr.sum()))


@dataclasses.dataclass(frozen=True)
class _Output:
    """The output's means and what every candidate is fitted against: the network (``x``,
    ``params``, ``act``, ``s``), one set of Monte Carlo draws (``seed``) with the columns and scales
    of the programmed model's propagation, the per-input means ``ybar`` (n o,), their weights and
    the programmed model's residual ``e0``."""

    x: np.ndarray
    params: list
    act: str
    s: float
    seed: object
    scales: object
    cols: dict
    hidden: list
    o: int
    ybar: np.ndarray
    var_y: np.ndarray
    w: np.ndarray
    sw: np.ndarray
    kappa: float
    sd: float
    e0: np.ndarray
    ds: np.ndarray

    @property
    def N(self) -> int:
        return self.ybar.size

    def zval(self, q, k):
        """A lack of fit ``q`` on ``k`` parameters in standard deviations of its null spread."""
        return (q - (self.N * self.kappa - k)) / max(self.sd, 1e-300)

    def propagate(self, deform=None, **kw):
        return _propagate(self.x, self.params, self.act, self.s, self.seed, self.scales, deform, **kw)

    def through_model(self, deform):
        """The lack of fit of the model with ``deform`` in place, weighed by its own Monte Carlo
        variance, and its residual."""
        m_t, v_t = self.propagate(deform)[:2]
        e_t = self.ybar - m_t.ravel()
        return float(np.sum(e_t * e_t / (self.var_y + v_t / DRAWS).ravel())), e_t


#: the step in relative s of the noise level's column (a central difference)
_H = 0.02


def _output(meas: Measurement, s: float, seed) -> _Output:
    act = meas.activation if meas.activation in _ACT else "tanh"
    x = np.asarray(meas.x, np.float64)
    params = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in meas.params]
    Y = np.asarray(meas.y, np.float64)
    n, r, o = Y.shape
    seed = _draws_for(x, params, seed)  # one set of draws for every propagation below
    mu, vmc, cols, scales = _propagate(x, params, act, s, seed, columns=True)
    mu_p = _propagate(x, params, act, s, seed, scales, {("s", 0): _H})[0]
    mu_m = _propagate(x, params, act, s, seed, scales, {("s", 0): -_H})[0]
    ds = ((mu_p - mu_m) / (2 * _H)).reshape(-1, 1)  # per unit of relative s
    ybar = Y.mean(1).ravel()
    w = (Y.var(1, ddof=1) / r + vmc / DRAWS).ravel()
    kappa = (r - 1) / (r - 3) if r > 3 else 3.0
    return _Output(x, params, act, s, seed, scales, cols, list(range(1, len(params))), o, ybar,
                   Y.var(1, ddof=1) / r, w, 1.0 / np.sqrt(w), kappa, _null_spread(Y, kappa), ybar - mu.ravel(), ds)


def _linear_fits(out: _Output) -> list:
    """Each candidate's linearised fit: [spec, weighted design, theta, lack of fit]."""
    N = out.N
    fits = []
    for spec in _specs(len(out.params), out.cols):
        J = np.concatenate([out.ds] + [_block(out.cols, *b, out.hidden).reshape(N, -1) for b in spec.blocks], axis=1)
        if J.shape[1] > MAX_SHARE * N:
            continue
        A = J * out.sw[:, None]
        theta, *_ = np.linalg.lstsq(A, out.e0 * out.sw, rcond=None)
        res = out.e0 - J @ theta
        fits.append([spec, A, theta, float(np.sum(res * res / out.w))])
    return fits


def _refine(out: _Output, spec, A, theta_lin, want, s_free):
    """Levenberg-Marquardt from the programmed model (theta = 0, where the columns are): the
    first trial is the linear fit; a trial that does not lower the lack of fit is refused
    and the damping raised (a detector's gain and offset on 57 parameters: the linear fit's
    lack of fit z = 1 was z = 906 through the model, and plain Gauss-Newton went on to
    984). With ``s_free`` False the noise level stays where it is (its column zero). Each
    trial's lack of fit weighs by the deformed model's own Monte Carlo variance (a curve
    that bends the noise -- a square law's -- makes its draws' mean noisier than the
    programmed model's)."""
    N, sw, hidden, h = out.N, out.sw, out.hidden, _H
    theta, q, e, J = np.zeros_like(theta_lin), float(np.sum(out.e0 * out.e0 / out.w)), out.e0, A / sw[:, None]
    if not s_free:
        J = J.copy()
        J[:, 0] = 0.0
    mu, trials = 1e-6, 0
    while trials < LM_TRIALS:
        trials += 1
        Aw = J * sw[:, None]
        F = Aw.T @ Aw
        delta = np.linalg.solve(F + mu * np.diag(np.maximum(np.diag(F), 1e-12)) + 1e-12 * np.eye(len(F)),
                                Aw.T @ (e * sw))
        trial = theta + delta
        deform = _deform(spec, trial, out.cols, hidden, out.o)
        q_t, e_t = out.through_model(deform)
        if TRACE:
            print("   levenberg-marquardt", spec.name, "s free" if s_free else "s fixed", "trial z",
                  round(out.zval(q_t, A.shape[1]), 1), "mu", mu, file=sys.stderr)
        if q_t >= q:
            mu *= 10.0
            continue
        gain = q - q_t
        theta, q, e, mu = trial, q_t, e_t, mu / 10.0
        # done: the candidate clearly explains, or the step moved its lack of fit by less
        # than a quarter of a standard deviation
        if out.zval(q, A.shape[1]) < Z_PASS - 1.0 or gain < 0.25 * out.sd:
            break
        cols_t = out.propagate(deform, columns=True, want=want)[2]
        # the noise level's column at the new point too (a readout's curve bends the noise
        # into the mean: a square-law detector's E y^2 moves with s^2)
        ds_t = ((out.propagate({**deform, ("s", 0): deform[("s", 0)] + h})[0]
                 - out.propagate({**deform, ("s", 0): deform[("s", 0)] - h})[0]
                 ).reshape(-1, 1) / (2 * h) if s_free else np.zeros((N, 1)))
        J = np.concatenate([ds_t] + [_block(cols_t, *b, hidden).reshape(N, -1) for b in spec.blocks], axis=1)
    return theta, q


def _refined(out: _Output, f_) -> None:
    """A candidate that could pass, checked through the model itself (its fit and lack of fit set
    in place): the level's linearisation can send a trial far (a square law's mean moved by the
    noise level: its linear fit passed, the trials through the model did not), so a failing one
    is refined again at the level found."""
    spec, A, theta_lin, _ = f_
    hidden = out.hidden
    want = {(kind, l) for kind, l, _ in spec.blocks if kind not in ("shape*", "const")}
    want |= {("shape", h) for kind, _, _ in spec.blocks if kind == "shape*" for h in hidden}
    want |= {("beta", l) if l in hidden else ("bias", l) for kind, l, _ in spec.blocks if kind == "const"}
    theta, q = _refine(out, spec, A, theta_lin, want, True)
    if out.zval(q, A.shape[1]) >= Z_PASS:
        theta2, q2 = _refine(out, spec, A, theta_lin, want, False)
        if q2 < q:
            theta, q = theta2, q2
    f_[2], f_[3] = theta, q


def _curve_over_levels(out: _Output, f_) -> None:
    """The output's curve over a few noise levels (it is linear in its coefficients at any level:
    nothing nonlinear follows it; the level a square law leaves in the output's spread is not the
    chip's: 0.05 against 0.14), its best fit set in place when better."""
    L, N, hidden = len(out.params), out.N, out.hidden

    def at_level(k_s):
        m_k, _, cols_k, _ = _propagate(out.x, out.params, out.act, out.s * k_s, out.seed, out.scales, columns=True,
                                       want={("shape", L), ("bias", L)})
        e_k = out.ybar - m_k.ravel()
        J_k = np.concatenate([_block(cols_k, *b, hidden).reshape(N, -1) for b in f_[0].blocks], axis=1)
        th = np.r_[k_s - 1.0, np.linalg.lstsq(J_k * out.sw[:, None], e_k * out.sw, rcond=None)[0]]
        return out.through_model(_deform(f_[0], th, cols_k, hidden, out.o))[0], th

    tried = {k_s: at_level(k_s) for k_s in LEVELS}
    k_best = min(tried, key=lambda k_: tried[k_][0])
    for k_s in (k_best / 1.2, k_best * 1.2):  # one step finer around the grid's best
        tried[k_s] = at_level(k_s)
    k_best = min(tried, key=lambda k_: tried[k_][0])
    if tried[k_best][0] < f_[3]:
        f_[3], f_[2] = tried[k_best]


def explain(meas: Measurement, s: float, seed: int = 20261127) -> list:
    """Each candidate mechanism with its lack of fit of the output's per-input mean (no taps),
    sorted by lack of fit: every candidate's linearised fit; those that could pass checked
    through the model itself (a dead neuron is not a small deformation, nor do the deformations
    of several layers add up linearly: Levenberg-Marquardt through propagations with the
    deformation in place, the same draws); the output's curve, when it is the closest and still
    fails, over a few noise levels."""
    out = _output(meas, s, seed)
    fits = _linear_fits(out)
    lin = {id(f_): out.zval(f_[3], f_[1].shape[1]) for f_ in fits}
    cand = sorted((f_ for f_ in fits if f_[0].blocks and lin[id(f_)] < REFINE_Z), key=lambda f_: lin[id(f_)])
    neurons = [f_ for f_ in cand if f_[0].blocks[0][2] is not None][:2]
    cand = [f_ for f_ in cand if f_[0].blocks[0][2] is None][:REFINE] + neurons
    refined = set()
    for f_ in cand:
        _refined(out, f_)
        refined.add(id(f_))
    done = [f_ for f_ in fits if id(f_) in refined]
    curve = [f_ for f_ in done if f_[0].name == CURVE]
    if curve and min(done, key=lambda f_: out.zval(f_[3], f_[1].shape[1])) is curve[0] \
            and out.zval(curve[0][3], curve[0][1].shape[1]) >= Z_PASS:
        _curve_over_levels(out, curve[0])
    found = []
    for f_ in fits:
        spec, A, theta, q = f_
        k = A.shape[1]
        if spec.blocks and id(f_) not in refined and lin[id(f_)] < REFINE_Z:
            continue  # could pass on its linearisation alone, but was not checked: not reported
        z = out.zval(q, k)
        found.append(OutputCandidate(spec.mechanism, spec.name, spec.layers, int(k), q, float(z),
                                     float(stats.norm.sf(z)), float(q + k * np.log(out.N))))
    return sorted(found, key=lambda c: c.z)


def order_map_classes(mechs: list, candidates) -> list:
    """The mechanism list with the output's explanations applied (no taps): when the programmed
    model does not reproduce the output's mean but a candidate mechanism does, its class leads
    (by the information criterion :attr:`OutputCandidate.bic`: the fewest parameters unless more of
    them fit clearly better), scored at
    least by how far it lowers the lack of fit, with the candidate named in its evidence; a map
    class no candidate of which explains the mean follows them. A class that explains but was
    not listed is added (its p-value: the chi-square of the lack of fit it removes) -- only when
    the list already holds a map class: the identification's calibrated tests decide that the
    mean map is wrong, the candidates only why. Noise
    classes keep their places: the leads take the first map class's. Unchanged when the programmed mean passes or
    no candidate explains (what then remains is said by the tests)."""
    cands = list(candidates)
    prog = next((c for c in cands if c.mechanism == "none"), None)
    if prog is None or prog.explains:
        return list(mechs)
    passing = sorted((c for c in cands if c.explains and c.mechanism in MAP_CLASSES), key=lambda c: c.bic)
    if not passing or not any(m["mechanism"] in MAP_CLASSES for m in mechs):
        # re-attribution only: the identification's own (calibrated) tests must find the mean
        # map wrong before a candidate names why
        return list(mechs)
    lead, seen = [], set()
    for c in passing:
        if c.mechanism in seen:
            continue
        seen.add(c.mechanism)
        improvement = float(prog.z - c.z)
        dq = max(prog.q - c.q, 0.0)
        p = float(stats.chi2.sf(dq, max(c.k - prog.k, 1)))
        text = (f"put into the model, {c.name} explains the output's mean (lack of fit z = {c.z:.1f} with "
                f"{c.k} parameters, the programmed model's z = {prog.z:.1f})")
        old = next((m for m in mechs if m["mechanism"] == c.mechanism), None)
        if old is not None:
            lead.append(dict(old, layers=sorted(set(c.layers)), score=max(float(old["score"]), improvement),
                             evidence=text + "; " + old["evidence"], p_value=min(float(old["p_value"]), p)))
        else:
            lead.append({"mechanism": c.mechanism, "layers": sorted(set(c.layers)), "score": improvement,
                         "evidence": text, "p_value": p})
    out, placed = [], False
    for m in mechs:
        if m["mechanism"] in MAP_CLASSES:
            if not placed:
                out.extend(lead)
                placed = True
            if m["mechanism"] in seen:
                continue
        out.append(m)
    return out if placed else out + lead


def summary(candidates, limit: int = 8) -> list[dict]:
    """The JSON of the candidates worth reading: the programmed model, every candidate that
    explains the output's mean (by information criterion), then each remaining class's best, at
    most ``limit`` rows besides the programmed one."""
    cands = list(candidates)
    prog = [c for c in cands if c.mechanism == "none"]
    passing = sorted((c for c in cands if c.explains and c.mechanism != "none"), key=lambda c: c.bic)
    rest, seen = [], {c.mechanism for c in passing}
    for c in sorted(cands, key=lambda c: c.z):
        if c.mechanism not in seen and c.mechanism != "none":
            seen.add(c.mechanism)
            rest.append(c)
    return [c.to_dict() for c in prog + (passing + rest)[:limit]]


#: without taps, classes of the mean map that the output cannot tell apart (an activation's
#: shape from a readout's transfer): one group for :func:`mean_refusal`
_GROUPS = {"activation_mismatch": "transfer", "readout_nonlinearity": "transfer"}


def _group(cls: str) -> str:
    return _GROUPS.get(cls, cls)


def mean_refusal(classes, candidates) -> str | None:
    """Why a fitted effect of ``classes`` does not explain the output's mean, or None: every
    candidate of its classes' group (a transfer's classes are one group without taps), put into
    the model and fitted to every input's mean, leaves a lack of fit beyond :data:`Z_PASS`, while
    a candidate of another group of the mean map reproduces it. None when its classes have no
    candidate here (noise classes) or none was checked through the model."""
    mine = {_group(c) for c in classes if c in MAP_CLASSES}
    if not mine:
        return None
    own = [c for c in candidates if _group(c.mechanism) in mine]
    other = [c for c in candidates if c.mechanism in MAP_CLASSES and _group(c.mechanism) not in mine and c.explains]
    if not own or any(c.explains for c in own) or not other:
        return None
    best, alt = min(own, key=lambda c: c.z), min(other, key=lambda c: c.bic)
    return (f"put into the model and fitted to every input's mean, {best.mechanism} does not reproduce the "
            f"output's mean (its best, {best.name}: lack of fit z = {best.z:.1f}), while {alt.name} does "
            f"(z = {alt.z:.1f}): the held-out test passes what the means reject")


def also_explaining(classes, candidates) -> str | None:
    """Without taps: the sentence naming the candidates of other groups of the mean map (a
    transfer's two classes are one group) that reproduce the output's mean as well as a fitted
    effect of ``classes`` explains the data, or None. The output alone cannot tell them apart:
    the detectors' gain and offset were explained by layer_gain while each output neuron's own
    gain and offset reproduced the mean too (z = 0.5 against a gain on every layer's 1.8)."""
    mine = {_group(c) for c in classes}
    other = sorted((c for c in candidates if c.explains and c.mechanism in MAP_CLASSES
                    and _group(c.mechanism) not in mine), key=lambda c: c.bic)
    if not other:
        return None
    seen, names = set(), []
    for c in other:
        if c.mechanism not in seen:
            seen.add(c.mechanism)
            names.append(f"{c.name} ({c.mechanism}, lack of fit z = {c.z:.1f})")
    return ("without taps the output's mean is reproduced as well by " + "; ".join(names[:3])
            + ": the output alone does not tell these apart (taps on the hidden layers would)")
