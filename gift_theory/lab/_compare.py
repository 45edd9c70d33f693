"""Compare a model with measurements: a discrepancy, its noise floor and a calibrated p-value.

A *cell* is one input i x one measured layer l (taps, then the output), seen as the vector
of the layer's neurons over the r repeated shots. Each cell gives five *channels*, each an
unbiased estimate of a population quantity that is >= 0 and is 0 when the model's law of
the cell equals the device's:

``energy``
    the U-statistic energy distance between model shots M and measured shots Y of the
    vector over neurons (correlations count)::

        E_il = 2 mean_{a,b} |M_a - Y_b| - mean_{a!=a'} |M_a - M_a'| - mean_{b!=b'} |Y_b - Y_b'|

    (the V-statistic of ``scipy.stats.energy_distance`` keeps the zero diagonal and is
    biased: a correct model could beat its own floor with it), over the layer's pooled
    within-data spread;
``energy_marginal``
    the same of each neuron's 1-D marginal, averaged over neurons;
``variance``, ``correlation``, ``shape``
    *split-half products* of a cell feature f -- per-neuron log variance, log of the top
    eigenvalue of the shot covariance (a common gain: rank-one correlation), pooled
    standardised fourth moment (the noise law at equal variance): the measured shots are
    split into halves A and B of h = r/2 shots, the model's into disjoint sets of h, and
    ``(f(Y_A) - f(M_A)) (f(Y_B) - f(M_B))`` (f(M) averaged over the model's sets) has
    expectation ``(E f(Y_h) - E f(M_h))^2`` for samples of the same size h: zero for a
    correct model whatever f is, positive otherwise. The energy distance alone barely sees
    a variance pattern or a law change at equal variance; these moments do.

Inputs are independent, so per channel c the cell values over inputs give a Student t
statistic t_c (mean over its standard error); transformed to the normal scale, z_c. The
**discrepancy** is the one-sided chi-square-like sum::

    Q = sum_c max(z_c, 0)^2            (over every channel of every measured layer)

lower is better; a channel that a model gets wrong adds about n times its squared effect,
one it gets right adds noise only. Its distribution under the model follows from the
correlation of the channels across inputs (estimated from the same inputs): Q of
z ~ N(0, R), by Monte Carlo (2e4 draws, fixed seed; beyond the simulated range the
Satterthwaite tail of sum z^2 bounds it). That gives the **p-value** (the probability,
under the model, of a discrepancy at least as large) and **se** (the standard deviation
of Q under the model). The **noise floor** is the same statistic between random halves
of the measured shots (the moment channels then use quarters). Measured calibration in
:mod:`gift_theory.lab.calibrate` (false alarms at p < 0.01 over null data sets).
"""

from __future__ import annotations

import dataclasses
import functools
import zlib

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from .._errors import GiftInputError
from .._model import forward, layer_step, sample_noise
from .._params import Layer
from ._measurement import Measurement


@dataclasses.dataclass(frozen=True)
class Model:
    """A model of the device: physics plus the weights it believes are programmed.

    ``params`` differ from the measurement's programmed weights only when a fitted
    ``weight_error`` correction has been estimated (``W + E_hat``).
    """

    physics: object
    params: tuple | None = None
    extra: dict = dataclasses.field(default_factory=dict)

    @property
    def effects(self) -> list[str]:
        names = list(self.physics.names)
        if "weight_error" in self.extra:
            names.append("weight_error")
        return names

    def params_json(self) -> dict:
        out = {k: float(v) for k, v in self.physics.params().items()}
        out.update({k: float(v) for k, v in self.extra.items()})
        return out

    def describe(self) -> str:
        d = self.physics.describe()
        if "weight_error" in self.extra:
            d += f" + weight_error(e={self.extra['weight_error']:.4g}, fitted offsets)"
        return d


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Result of :func:`compare`.

    discrepancy : Q = sum_c max(z_c, 0)^2 over the channels of every measured layer
    se : standard deviation of Q under the model (its scale of pure noise)
    noise_floor : the same statistic between random halves of the measured shots
    floor_se : its standard deviation under the model
    p_value : P(Q' >= Q) under the model
    per_input : (n,) mean over channels of each input's channel values in floor units
    per_layer : (L',) the part of Q each measured layer contributes
    layer_ids : the 1-based layer of each entry of per_layer
    cells : (n, L') per input and layer, the mean of the channel values in floor units
    channel_z : (L', C) z of every channel (rows: layers, columns: :data:`CHANNELS` used)
    channels : the names of the columns of channel_z
    net_discrepancy : for a model with fitted offsets scored against a refit null
        (``compare(..., null_replicates=...)``): Q net of what the offsets' estimation error
        alone adds, the statistic of ``p_value``; ``discrepancy`` stays the raw held-out Q
        (what ranking by held-out error needs: estimation error is part of a model's cost)
    replicates : number of refit-null replicates behind ``p_value`` (0: none needed)
    """

    discrepancy: float
    se: float
    noise_floor: float
    floor_se: float
    p_value: float
    per_input: np.ndarray
    per_layer: np.ndarray
    layer_ids: tuple
    cells: np.ndarray
    channel_z: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    channels: tuple = ()
    net_discrepancy: float | None = None
    replicates: int = 0

    def as_dict(self) -> dict:
        extra = {} if not self.replicates else {"net_discrepancy": self.net_discrepancy,
                                                 "refit_null_replicates": self.replicates}
        return {**extra, "discrepancy": self.discrepancy, "se": self.se, "noise_floor": self.noise_floor,
                "floor_se": self.floor_se, "p_value": self.p_value,
                "per_layer": {f"layer{l}": float(v) for l, v in zip(self.layer_ids, self.per_layer)},
                "channel_z": {f"layer{l}": {c: float(z) for c, z in zip(self.channels, row)}
                              for l, row in zip(self.layer_ids, self.channel_z)}}


def _pair_dist(A, B):
    """(..., K, d), (..., r, d) -> (..., K, r) Euclidean distances."""
    sq = (jnp.sum(A * A, -1)[..., :, None] + jnp.sum(B * B, -1)[..., None, :]
          - 2.0 * jnp.einsum("...kd,...rd->...kr", A, B))
    return jnp.sqrt(jnp.maximum(sq, 0.0))


def _offdiag_mean(D):
    k = D.shape[-1]
    return (jnp.sum(D, (-2, -1)) - jnp.trace(D, axis1=-2, axis2=-1)) / (k * (k - 1))


def _pairsum(Z):
    """(n, N, d) -> (n, d): sum over unordered pairs of |Z_a - Z_b| per neuron, by sorting."""
    N = Z.shape[1]
    k = jnp.arange(1, N + 1, dtype=Z.dtype)[None, :, None]
    return jnp.sum(jnp.sort(Z, axis=1) * (2.0 * k - N - 1.0), axis=1)


@functools.partial(jax.jit, static_argnames=("paired",))
def energy_cells(M, Y, paired: bool = False):
    """Unbiased energy distances per cell: of the vector over neurons and of each neuron.

    Parameters
    ----------
    M : (n, K, d) model shots
    Y : (n, r, d) measured shots
    paired : M_a and Y_a share a shot (one-step check); then the cross terms drop a == b

    Returns
    -------
    E : (n,) U-statistic energy distance of the vectors
    wy : (n,) mean_{b != b'} |Y_b - Y_b'|
    E1 : (n, d) U-statistic energy distance of each neuron's marginal (1-D, sharper on shape)
    wy1 : (n, d) its within-data spread
    """
    c = jnp.mean(Y, axis=1, keepdims=True)  # centring keeps float32 distances accurate
    M = M - c
    Y = Y - c
    cross = _pair_dist(M, Y)
    cross = _offdiag_mean(cross) if paired else jnp.mean(cross, (-2, -1))
    wm = _offdiag_mean(_pair_dist(M, M))
    wy = _offdiag_mean(_pair_dist(Y, Y))
    K, r = M.shape[1], Y.shape[1]
    pm, py = _pairsum(M), _pairsum(Y)
    c1 = _pairsum(jnp.concatenate([M, Y], axis=1)) - pm - py  # all cross pairs
    if paired:
        c1 = (c1 - jnp.sum(jnp.abs(M - Y), axis=1)) / (K * r - K)
    else:
        c1 = c1 / (K * r)
    wm1 = 2.0 * pm / (K * (K - 1))
    wy1 = 2.0 * py / (r * (r - 1))
    return 2.0 * cross - wm - wy, wy, 2.0 * c1 - wm1 - wy1, wy1


def cell_statistic(M, Y, paired: bool = False, scales=None):
    """The two normalised channels of a cell, shape (n, 2): the vector energy distance over
    the layer's pooled spread, and the mean over neurons of each neuron's energy distance
    over its pooled spread.

    ``scales`` (from :func:`layer_scales`) fixes the normalisation; default: from ``Y``.
    """
    E, wy, E1, wy1 = energy_cells(M, Y, paired)
    E, wy, E1, wy1 = (np.asarray(a, np.float64) for a in (E, wy, E1, wy1))
    if scales is None:
        scales = (wy.mean(), wy1.mean(0))
    S, S1 = scales
    return np.stack([E / max(S, 1e-30), np.mean(E1 / np.maximum(S1, 1e-30), axis=1)], axis=1)


def layer_scales(Y):
    """The pooled within-data spreads of a measured layer Y (n, r, d): ``(S, S1 (d,))``."""
    Y = jnp.asarray(Y, jnp.float32)
    _, wy, _, wy1 = energy_cells(Y[:, :2], Y)
    return float(np.mean(np.asarray(wy, np.float64))), np.asarray(wy1, np.float64).mean(0)


def _shot_permutations(key, n: int, r: int):
    """(n, r): a random permutation of the r shots of each of n inputs."""
    return jax.vmap(lambda k: jax.random.permutation(k, r))(jax.random.split(key, n))


def _halves(key, Y):
    """Random halves (per cell) of the measured shots: two (n, r//2, d) arrays."""
    n, r, _ = Y.shape
    perm = _shot_permutations(key, n, r)
    Yp = jnp.take_along_axis(Y, perm[:, :, None], axis=1)
    h = r // 2
    return Yp[:, :h], Yp[:, h:2 * h]




def draws(key, physics, arch, batch_shape):
    """Standard draws of ``physics`` for ``batch_shape`` shots, as the core's ``sample_noise``
    defines them (unit variance; the additive sites follow the physics' law), made with
    numpy: no compilation per physics structure, and each site's draws depend only on
    ``key`` and the site's name (common random numbers across candidate models)."""
    from ..effects.awgn import additive_sites

    seed = [int(v) for v in np.asarray(jax.random.key_data(key)).ravel()]
    additive = set(additive_sites(arch)) if "awgn" in physics else set()
    law = physics.law
    out = {}
    for name, event in physics.draws(arch).items():
        rng = np.random.default_rng(seed + [zlib.crc32(name.encode())])
        shape = tuple(batch_shape) + tuple(event)
        if name in additive and law == "laplace":
            a = rng.laplace(0.0, 1.0 / np.sqrt(2.0), shape)
        elif name in additive and law == "uniform":
            a = rng.uniform(-np.sqrt(3.0), np.sqrt(3.0), shape)
        else:
            a = rng.standard_normal(shape)
        out[name] = jnp.asarray(a, jnp.float32)
    return out


@functools.partial(jax.jit, static_argnames=("arch",))
def layer_outputs(params, x, noise, physics, arch, t):
    """Every layer's output a_1..a_L for inputs x (n, d_0) and draws of batch (n, K)
    (jitted core ``forward``; compiled once per physics structure and shape, shared by the
    fit and the comparison)."""
    return forward(params, x[:, None, :], noise, physics, arch, t=t, taps=True).taps


def params32(params):
    """Weights as float32 :class:`Layer` s (what every jitted pass of the lab takes)."""
    return tuple(Layer(jnp.asarray(W, jnp.float32), jnp.asarray(b, jnp.float32)) for W, b in params)


def default_model_shots(r: int) -> int:
    """Model shots per input when not told: 4 r (the model's own sampling noise in the
    statistic then is a quarter of the data's, so candidates differ by physics, not luck)."""
    return 4 * int(r)


def _times(meas: Measurement, K: int):
    if meas.t is None:
        return None
    reps = -(-K // meas.r)
    return jnp.asarray(np.tile(meas.t, (1, reps))[:, :K], jnp.float32)


def model_shots(key, model: Model, meas: Measurement, shots: int | None = None):
    """Shots of the model for the measurement's inputs (and times): one (n, K, d_l) array per
    measured layer (taps then output). ``K = shots`` (default 4 r); times are the measured
    ones, tiled when K exceeds r."""
    K = default_model_shots(meas.r) if shots is None else int(shots)
    params = params32(model.params if model.params is not None else meas.params)
    # in chunks of 2 r shots: the shape the fit compiled for, so no second compilation
    chunk = 2 * meas.r if K % (2 * meas.r) == 0 else K
    x = jnp.asarray(meas.x, jnp.float32)
    parts = []
    for c in range(K // chunk):
        noise = draws(jax.random.fold_in(key, c), model.physics, meas.arch, (meas.n, chunk))
        parts.append(layer_outputs(params, x, noise, model.physics, meas.arch, _times(meas, chunk)))
    outs = parts[0] if len(parts) == 1 else tuple(jnp.concatenate(p, axis=1) for p in zip(*parts))
    return tuple(outs[l - 1] for l in meas.layer_ids())


def _student_p(T):
    n = T.shape[0]
    mean = float(np.mean(T))
    se = float(np.std(T, ddof=1) / np.sqrt(n)) if n > 1 else float("inf")
    if not np.isfinite(se) or se <= 0:
        return mean, se, (1.0 if mean <= 0 else 0.0)
    return mean, se, float(stats.t.sf(mean / se, df=n - 1))


# ---- the moment channels ------------------------------------------------------------------

#: every channel of a cell, in order (the moment channels need r >= 8 shots)
CHANNELS = ("energy", "energy_marginal", "variance", "correlation", "shape")
#: fewest shots per input for the moment channels (their noise floor splits shots in quarters)
MIN_SHOTS_MOMENTS = 8


def _variance_floor(Y):
    """A variance floor of a measured layer Y (n, r, d) for the features (a data constant)."""
    return 1e-3 * float(np.mean(np.var(Y, axis=1)) + 1e-30)


def _features(S, eps):
    """Cell features of samples S (n, h, d): per-neuron log variance (n, d), log top
    eigenvalue of the shot covariance (n, 1), pooled standardised fourth moment (n, 1).
    ``eps`` (a variance floor of the layer, a data constant) keeps quantised cells finite."""
    c = S - S.mean(axis=1, keepdims=True)
    h = S.shape[1]
    v = np.sum(c * c, axis=1) / (h - 1)
    cov = np.einsum("nkd,nke->nde", c, c) / (h - 1)
    lmax = np.linalg.eigvalsh(cov)[:, -1] if S.shape[2] > 1 else v[:, 0]
    z = c / np.sqrt(v + eps)[:, None, :]
    return (np.log(v + eps), np.log(np.maximum(lmax, 0.0) + eps)[:, None], np.mean(z ** 4, axis=(1, 2))[:, None])


def _product_channels(YA, YB, MA, MB, eps):
    """(n, 3) split-half products of the features: mean over each feature's columns of
    (f(YA) - f(MA)) (f(YB) - f(MB)); ``MA``/``MB`` are lists of model samples (averaged)."""
    def avg(samples):
        fs = [_features(m, eps) for m in samples]
        return [sum(f[j] for f in fs) / len(fs) for j in range(3)]

    fya, fyb = _features(YA, eps), _features(YB, eps)
    fma, fmb = avg(MA), avg(MB)
    return np.stack([np.mean((fya[j] - fma[j]) * (fyb[j] - fmb[j]), axis=1) for j in range(3)], axis=1)


def _take(Y, idx):
    return np.take_along_axis(Y, idx[:, :, None], axis=1)


def moment_channels(M, Y, split, rng):
    """The moment channels of one measured layer, (n, 3).

    Parameters
    ----------
    M : (n, K, d) model shots, K >= r
    Y : (n, r, d) measured shots
    split : (n, r) a permutation of each input's shots: the first h = r // 2 are half A,
        the next h half B (fixed per measurement, the same for every model)
    rng : numpy Generator for the model's disjoint sets of h shots
    """
    M = np.asarray(M, np.float64)
    Y = np.asarray(Y, np.float64)
    n, r, _ = Y.shape
    h = r // 2
    K = M.shape[1]
    if K < 2 * h:
        raise GiftInputError(f"compare: {K} model shots per input; the moment channels need at least {2 * h}")
    eps = _variance_floor(Y)
    reps = K // (2 * h)
    perm = rng.permuted(np.tile(np.arange(K), (n, 1)), axis=1)
    MA = [_take(M, perm[:, 2 * q * h:(2 * q + 1) * h]) for q in range(reps)]
    MB = [_take(M, perm[:, (2 * q + 1) * h:(2 * q + 2) * h]) for q in range(reps)]
    return _product_channels(_take(Y, split[:, :h]), _take(Y, split[:, h:2 * h]), MA, MB, eps)


def floor_moment_channels(Y, split):
    """The moment channels between the halves of the measured shots (quarters of r/4 shots)."""
    Y = np.asarray(Y, np.float64)
    q = Y.shape[1] // 4
    eps = _variance_floor(Y)
    A1, A2, B1, B2 = (_take(Y, split[:, i * q:(i + 1) * q]) for i in range(4))
    return _product_channels(B1, B2, [A1], [A2], eps)


# ---- the test ----------------------------------------------------------------------------

#: Monte Carlo draws of the null distribution of Q (fixed seed: same data, same p-value)
NULL_DRAWS = 20_000


def _z_scores(T, shift=None, extra_var=None):
    """Per column of T (n, C): the one-sided Student t, on the normal scale. Columns with
    no spread carry no information (z = 0). ``shift`` (C,) is subtracted from the column
    means and ``extra_var`` (C,) added to their squared standard errors (a null whose mean
    is not zero: see :func:`q_test`)."""
    n = T.shape[0]
    mean = T.mean(axis=0) - (0.0 if shift is None else shift)
    sd = T.std(axis=0, ddof=1)
    ok = sd > 1e-12 * (np.abs(mean) + 1e-300)
    se = np.sqrt(np.where(ok, sd, 1.0) ** 2 / n + (0.0 if extra_var is None else extra_var))
    t = np.where(ok, mean / se, 0.0)
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        z = stats.norm.isf(stats.t.sf(t, df=n - 1))
    z = np.where(np.isfinite(z), z, t)  # far in the tails the t and normal scales agree to the reported digits
    return z, ok


def replicate_null(T_reps):
    """``(shift, extra_var)`` of :func:`q_test` from B replicate channel matrices (B, n, C)
    simulated under the null *with* the model's estimation: data from the fitted model as
    truth, parameters refitted on simulated fitting data, channels on simulated held-out
    data. ``shift`` is the replicates' mean channel value (what estimation error alone
    adds); ``extra_var`` is the part of the variance of a channel's mean that inputs do not
    average away (an estimation error is shared by every held-out input), over and above
    the within-inputs standard error, inflated by 1 + 1/B for the estimated shift."""
    T_reps = np.asarray(T_reps, np.float64)
    B, n = T_reps.shape[:2]
    means = T_reps.mean(axis=1)  # (B, C)
    shift = means.mean(axis=0)
    within = np.mean(T_reps.var(axis=1, ddof=1), axis=0) / n
    between = means.var(axis=0, ddof=1) if B > 1 else np.zeros_like(shift)
    extra = np.maximum(between - within, 0.0) * (1.0 + 1.0 / B) + within / B
    return shift, extra


def q_test(T, shift=None, extra_var=None):
    """The discrepancy test on per-input channel values T (n, C).

    ``shift`` and ``extra_var`` (C,) describe a null under which the channel means are not
    zero (a model with many fitted parameters scored on held-out inputs: its estimation
    error raises the mean-sensitive channels; :func:`replicate_null`).

    Returns
    -------
    Q, p_value, null_mean, null_sd, z (C,)
    """
    z, ok = _z_scores(T, shift, extra_var)
    Q = float(np.sum(np.maximum(z, 0.0) ** 2))
    Tk = T[:, ok]
    if Tk.shape[1] == 0 or T.shape[0] < 3:
        return Q, 1.0, 0.0, 0.0, z
    R = np.atleast_2d(np.corrcoef(Tk, rowvar=False))
    lam, V = np.linalg.eigh(R)
    lam = np.clip(lam, 0.0, None)
    G = np.random.default_rng(0).standard_normal((NULL_DRAWS, len(lam))) @ (V * np.sqrt(lam)).T
    Qs = np.sum(np.maximum(G, 0.0) ** 2, axis=1)
    exceed = int(np.sum(Qs >= Q))
    if exceed > 0:
        p = (1 + exceed) / (NULL_DRAWS + 1)
    else:  # beyond the simulation: Q <= sum z^2, whose tail is Satterthwaite's a chi2_b
        tr1, tr2 = float(np.sum(lam)), float(np.sum(lam ** 2))
        p = min(max(float(stats.chi2.sf(Q * tr1 / tr2, df=tr1 * tr1 / tr2)), 1e-300), 1.0 / (NULL_DRAWS + 1))
    return Q, float(p), float(Qs.mean()), float(Qs.std(ddof=1)), z


@dataclasses.dataclass(frozen=True)
class Reference:
    """What a measurement contributes to every comparison, computed once.

    scales : per measured layer, the pooled within-data spreads (S_l, S1_l (d_l,))
    split : (n, r) per input, the permutation of its shots that defines the halves A, B
    channels : the channels in use (:data:`CHANNELS`, or the energy ones when r < 8)
    weights : (L', C) one over each channel's standard deviation across inputs between
        halves of the measured shots (for the per-input summaries only)
    noise_floor, floor_se : Q between random halves of the measured shots, and Q's
        standard deviation under the model
    floor_per_input : (n,)
    """

    scales: tuple
    split: np.ndarray
    channels: tuple
    weights: np.ndarray
    noise_floor: float
    floor_se: float
    floor_per_input: np.ndarray


def _combine(C, weights):
    """(n, L', C) channels -> per input (n,) and per cell (n, L'): means in floor units."""
    Cw = C * weights[None]
    return Cw.mean(axis=(1, 2)), Cw.mean(axis=2)


def reference(key, meas: Measurement, splits: int = 2) -> Reference:
    """Scales, the shot split, channel weights and the noise floor of ``meas``: the
    discrepancy statistic between random halves of the measured shots (energy channels
    averaged over ``splits`` random splits)."""
    if meas.r < 4:
        raise GiftInputError(f"measurement has {meas.r} shots per input; the noise floor (random halves) needs at least 4")
    if meas.n < 3:
        raise GiftInputError(f"measurement has {meas.n} inputs; the p-value (over inputs) needs at least 3")
    layers = meas.layers()
    scales = tuple(layer_scales(Y) for Y in layers)
    k_split, k_floor = jax.random.split(key)
    split = np.asarray(_shot_permutations(k_split, meas.n, meas.r))
    moments = meas.r >= MIN_SHOTS_MOMENTS
    channels = CHANNELS if moments else CHANNELS[:2]
    F = np.zeros((meas.n, len(layers), len(channels)))
    for li, Y in enumerate(layers):
        for s_ in range(splits):
            A, B = _halves(jax.random.fold_in(k_floor, s_ * 101 + li), jnp.asarray(Y, jnp.float32))
            F[:, li, :2] += cell_statistic(A, B, scales=scales[li]) / splits
        if moments:
            F[:, li, 2:] = floor_moment_channels(Y, split)
    sd = F.std(axis=0, ddof=1)
    weights = 1.0 / np.maximum(sd, 1e-12 * max(float(sd.max()), 1e-300))
    Q, _, _, null_sd, _ = q_test(F.reshape(meas.n, -1))
    Fi, _ = _combine(F, weights)
    return Reference(scales, split, channels, weights, Q, null_sd, Fi)


def noise_floor(key, meas: Measurement, splits: int = 2):
    """``(floor, floor_se)``: see :func:`reference`."""
    ref = reference(key, meas, splits)
    return ref.noise_floor, ref.floor_se


def channel_values(key, model: Model, meas: Measurement, ref: Reference, shots: int | None = None) -> np.ndarray:
    """The channels of every cell, (n, L', C): input x measured layer x channel of ``ref``."""
    if shots is not None and int(shots) < meas.r:
        raise GiftInputError(f"compare: --shots {shots} model shots per input; at least the measured {meas.r} needed")
    Ms = model_shots(key, model, meas, shots)
    rng = np.random.default_rng(np.asarray(jax.random.key_data(jax.random.fold_in(key, 7))).ravel())
    C = np.zeros((meas.n, len(Ms), len(ref.channels)))
    for li, (M, Y, sc) in enumerate(zip(Ms, meas.layers(), ref.scales)):
        C[:, li, :2] = cell_statistic(M, jnp.asarray(Y, jnp.float32), scales=sc)
        if len(ref.channels) > 2:
            C[:, li, 2:] = moment_channels(M, Y, ref.split, rng)
    return C


def compare(key, model: Model, meas: Measurement, *, shots: int | None = None, ref: Reference | None = None,
            floor_splits: int = 2, null_replicates=None) -> Comparison:
    """Score ``model`` against ``meas`` (see the module docstring for the statistic).

    Parameters
    ----------
    key : PRNG key (split into ``model`` and ``floor`` subkeys)
    model : Model
    meas : Measurement (use held-out inputs for a fitted model)
    shots : model shots per input (default: 4 r; at least r)
    ref : the measurement's :class:`Reference` if already computed (same for every model)
    null_replicates : (B, n, L', C) channel values simulated under the null with the model's
        estimation error (:func:`gift_theory.lab.offset_replicates`); the test then allows
        for it (:func:`replicate_null`). Default: a model with no estimation error to speak of.

    Returns
    -------
    Comparison
    """
    k_model, k_floor = jax.random.split(key)
    if ref is None:
        ref = reference(k_floor, meas, floor_splits)
    C = channel_values(k_model, model, meas, ref, shots)
    L = C.shape[1]
    Q, p, _, null_sd, z = q_test(C.reshape(meas.n, -1))
    net, B = None, 0
    if null_replicates is not None:
        reps = np.asarray(null_replicates)
        B = reps.shape[0]
        shift, extra = replicate_null(reps.reshape(B, meas.n, -1))
        net, p, _, _, _ = q_test(C.reshape(meas.n, -1), shift, extra)
    zl = z.reshape(L, len(ref.channels))
    T, cells = _combine(C, ref.weights)
    return Comparison(discrepancy=Q, se=null_sd, noise_floor=ref.noise_floor, floor_se=ref.floor_se, p_value=p,
                      per_input=T, per_layer=np.sum(np.maximum(zl, 0.0) ** 2, axis=1), layer_ids=meas.layer_ids(),
                      cells=cells, channel_z=zl, channels=ref.channels, net_discrepancy=net, replicates=B)


def one_step_shots(key, model: Model, meas: Measurement, layer: int):
    """The model's layer ``layer`` fed with the *measured* output of the layer before, same
    shot (needs taps for layer >= 2; layer 1 is fed x). Returns (n, r, d_l)."""
    arch = meas.arch
    params = model.params if model.params is not None else meas.params
    W, b = (jnp.asarray(p, jnp.float32) for p in params[layer - 1])
    phys = model.physics
    n, r = meas.n, meas.r
    noise = sample_noise(key, arch, phys, (n, r), jnp.float32)
    t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)
    if layer == 1:
        a = jnp.asarray(meas.x, jnp.float32)[:, None, :]
        if "a0" in noise:
            a = a + phys.s * noise["a0"]
    else:
        a = jnp.asarray(meas.taps[layer - 2], jnp.float32)
    return layer_step(W, b, a, noise, phys, arch, layer, t=t)[0]


def one_step_check(key, model: Model, meas: Measurement, ref: Reference | None = None) -> list[dict]:
    """Per measured layer: the one-step discrepancy (layer model fed the measured previous
    layer, same shot), its se, z and p-value. Without taps only layer 1 can be fed (when the
    network has one layer, that is the output); deeper layers need the taps."""
    if ref is None:
        ref = reference(jax.random.fold_in(key, 999), meas)
    rows = []
    for li, (l, Y) in enumerate(zip(meas.layer_ids(), meas.layers())):
        if meas.taps is None and l > 1:
            continue
        M = one_step_shots(jax.random.fold_in(key, l), model, meas, l)
        C = cell_statistic(M, jnp.asarray(Y, jnp.float32), paired=True, scales=ref.scales[li])
        T = (C * ref.weights[li][None, :2]).mean(axis=1)
        D, se, p = _student_p(T)
        rows.append({"layer": l, "discrepancy": D, "se": se, "z": D / se if se > 0 else float("nan"), "p_value": p})
    return rows
