"""Stage 6 of the lab: where a model fails -- layers, neurons, inputs -- and each effect's signature there.

:class:`Residuals` holds, per measured layer, the measured shots against two disjoint halves
A and B of the model's shots: half A enters every residual, half B every scale and every
direction a residual is projected on, so a residual has mean exactly zero under the model
whatever its scale (a ratio of a variance to its own estimate would be biased). Statistics
are summed per input and tested over inputs (Student t on the normal scale): inputs are
independent, the neurons of one input are not (noise upstream reaches them all). Every
statistic of the model's shots is a function of one input's shots: on a large file they are
made a block of inputs at a time (:class:`ModelShots`), never held whole, and the numbers are
the whole array's, bit for bit.

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

import collections.abc
import dataclasses

import jax
import numpy as np
from scipy import stats

from .. import _random
from .._measurement import Measurement
from .._model import named_subkey
from ..effects import REGISTRY
from ._qtest import log_variance_bias, over_inputs
from ._shots import (
    block_inputs,
    central_slope,
    default_model_shots,
    Model,
    model_shots,
    noiseless_pre,
    noiseless_taps,
    one_step_block_inputs,
    one_step_pre,
    one_step_rows,
    one_step_shots,
    params32,
    shot_blocks,
    to32,
)


def _kurt(A):
    c = A - A.mean(1, keepdims=True)
    c2 = c * c  # squares, not pow (c ** 4): a tenth of the time
    v = np.mean(c2, 1)
    return np.mean(c2 * c2, 1) / np.maximum(v * v, 1e-300) - 3.0


class ModelShots:
    """The model's shots of every layer of a :class:`Residuals` (a tuple of (n, K, d_l) float32
    arrays), a block of inputs at a time: held whole when one block holds them, else made again
    on each reading by ``make`` (keyed draws: the same numbers, bit for bit), so a statistic
    computed input by input holds one block's shots, not the whole array's.

    ``blocks()`` yields ``(slice of inputs, tuple of the block's arrays)``."""

    def __init__(self, make, held=None):
        self._make, self._held = make, (None if held is None else tuple(held))

    @classmethod
    def whole(cls, shots) -> "ModelShots":
        """Shots already made, held."""
        return cls(None, tuple(shots))

    def blocks(self):
        if self._held is not None:
            yield slice(0, self._held[0].shape[0]), self._held
        else:
            yield from self._make()


class ModelHalf(collections.abc.Sequence):
    """One half of the model's shots, per layer: made or held as drawn (float32, half the
    memory of float64; :class:`ModelShots`) and read as float64 -- item ``l`` is layer ``l``'s
    half widened, which is exact, so every statistic reads the same numbers as from float64
    shots. :meth:`blocks` reads every layer's half a block of inputs at a time."""

    def __init__(self, shots: ModelShots, halves, n: int):
        self._shots, self._halves, self._n = shots, list(halves), int(n)

    def __len__(self) -> int:
        return len(self._halves)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        out = None
        for sl, M in self.blocks(layers=(i,)):  # a fresh array each read
            if out is None:
                out = np.empty((self._n,) + M[0].shape[1:], np.float64)
            out[sl] = M[0]
        return out

    def blocks(self, layers=None):
        """Yields ``(slice of inputs, [each layer's half of the block, float64])`` (``layers``:
        the indices to read, default every layer)."""
        ids = range(len(self)) if layers is None else layers
        for sl, M in self._shots.blocks():
            yield sl, [np.array(M[i][:, self._halves[i]], np.float64) for i in ids]


def _both_halves(MA, MB):
    """Yields ``(rows, [each layer's half A], [each layer's half B])`` a block of inputs at a time,
    both halves read from one making of the shots when they share it."""
    if isinstance(MA, ModelHalf) and isinstance(MB, ModelHalf) and MA._shots is MB._shots:
        for sl, M in MA._shots.blocks():
            yield sl, *([np.array(m[:, h], np.float64) for m, h in zip(M, half._halves)] for half in (MA, MB))
        return
    yield slice(0, np.shape(MA[0])[0]), [np.asarray(a, np.float64) for a in MA], [np.asarray(b, np.float64) for b in MB]


def half_shots(half, li: int) -> int:
    """Model shots per input in layer ``li``'s half (a :class:`ModelHalf` or a list of arrays)."""
    if isinstance(half, ModelHalf):
        return half._halves[li].stop - half._halves[li].start
    return int(np.shape(half[li])[1])


def half_blocks(half, layers=None):
    """:meth:`ModelHalf.blocks` of a half, or one block of a caller's own list of arrays."""
    if isinstance(half, ModelHalf):
        yield from half.blocks(layers)
        return
    ids = range(len(half)) if layers is None else layers
    yield slice(0, np.shape(half[0])[0]), [np.asarray(half[i], np.float64) for i in ids]


@dataclasses.dataclass
class Residuals:
    """Measured shots against a model, per measured layer (lists over layers, each (n, d_l)
    unless said).

    Y, MA, MB : (n, r, d), (n, K/2, d), (n, K/2, d) measured shots and the model's halves (MA, MB:
        :class:`ModelHalf`, each layer's shots read as float64 arrays; held in float32 when one
        block of :func:`~._shots.shot_blocks` holds them, else made again a block at a time:
        a statistic of each input's shots reads :meth:`ModelHalf.blocks` or
        :meth:`per_input_of_model_halves`)
    mean_resid : (md - mA) / sqrt(vB (1/r + 2/K)), ~ N(0, 1) per cell under the model
    var_resid : (vd - vA) / vB, mean zero under the model
    kurt_resid : excess kurtosis of the r measured shots minus that of r model shots (half A,
        averaged over its groups of r): the same estimator at the same size, mean zero
    mA : the model's per-cell mean from half A
    mB, vB : the model's per-cell mean and variance from half B (scales and directions)
    pre : the model's noiseless pre-activation z_l
    gain_dir : d(noiseless output)/d g of a gain g on the layer's weighted sum at g = 1:
        sigma'(z) u on a hidden layer, u on the output (u = z - b: the weighted sum)
    slope : d(noiseless output)/dz: sigma'(z) on a hidden layer, 1 on the output (the direction a
        shift of the bias moves the mean)
    t : (n, r) acquisition times or None
    paired : the model's shots were fed the measured inputs of the layer before (one-step;
        draw j of measured shot k at j r + k), not drawn on their own
    model_terms : per layer, what :func:`layer_evidence` reads of the model's shots, made with
        the residuals from the same shots: ``half_means`` (see :func:`_half_means`) and
        ``excess`` (the model's term of :func:`_excess_covariance`); None: read from MA, MB
    """

    meas: Measurement
    model: Model
    layer_ids: tuple
    Y: list
    MA: collections.abc.Sequence
    MB: collections.abc.Sequence
    mean_resid: list
    var_resid: list
    kurt_resid: list
    mA: list
    mB: list
    vB: list
    pre: list
    gain_dir: list
    slope: list
    t: np.ndarray | None
    paired: bool = False
    model_terms: list | None = None

    @property
    def n(self) -> int:
        return self.meas.n

    over_inputs = staticmethod(over_inputs)

    def score(self, e, w) -> float:
        """z of the residuals ``e`` projected on the direction ``w`` (lists over layers of (n, d)
        arrays, or one array): per input sum_j e_ij w_ij, tested over inputs."""
        e = e if isinstance(e, list) else [e]
        w = w if isinstance(w, list) else [w]
        T = sum(np.sum(np.asarray(a) * np.asarray(b), axis=-1) for a, b in zip(e, w))
        return over_inputs(T, "a residual score's per-input values (the residuals along a signature's direction)")

    def model_half_shots(self) -> list[int]:
        """Per layer, the model's shots per input in each half (K/2)."""
        return [half_shots(self.MA, li) for li in range(len(self.layer_ids))]

    def per_input_of_model_halves(self, f) -> list:
        """Per layer ``li``, ``f(li, rows, MA, MB)`` of the model's halves of a block of inputs
        (float64, (b, K/2, d)) put together over the blocks (each a (b, ...) array for those
        rows): a statistic of each input's model shots with one block of them in memory at a
        time (the shots of a large file are made a block at a time, once for every layer)."""
        out = [None] * len(self.layer_ids)
        for sl, MA, MB in _both_halves(self.MA, self.MB):
            for li, (a, b) in enumerate(zip(MA, MB)):
                v = np.asarray(f(li, sl, a, b))
                if out[li] is None:
                    out[li] = np.empty((self.n,) + v.shape[1:], v.dtype)
                out[li][sl] = v
        return out

    def mean_derivative(self, effect: str, param: str, at: float, h: float):
        """Per layer (n, d), d(noiseless model mean)/d param of ``effect`` added at ``at``
        (central difference of step h, every draw zero): the direction the effect would move
        the measured means."""
        out = []
        for sign in (1.0, -1.0):
            taps = noiseless_taps(self.model, self.meas, self.model.physics.with_effect(effect, **{param: at + sign * h}))
            out.append([taps[l - 1] for l in self.layer_ids])
        return [(p - m) / (2 * h) for p, m in zip(*out)]


def _directions(model: Model, meas: Measurement, layer: int, pre):
    """``(gain_dir, slope)`` of :class:`Residuals` for one layer: sigma'(z) u and sigma'(z) (hidden),
    u and 1 (output), u = z - b_eff the weighted sum."""
    b = np.asarray(model.physics.bias(params32(model.weights(meas))[layer - 1].b, layer, meas.arch.depth), np.float64)
    u = pre - b[None, :]
    if layer == meas.arch.depth:
        return u, np.ones_like(u)
    slope = np.asarray(central_slope(to32(pre), meas.arch.sigma), np.float64)
    return slope * u, slope


def _residuals_from(meas: Measurement, model: Model, layer_ids, shots: ModelShots, pres,
                    paired: bool = False) -> Residuals:
    """The residuals of ``layer_ids`` against the model's ``shots``, made in one pass over their
    blocks: every statistic below is a function of one input's shots, so it is the same, bit for
    bit, whatever the blocks."""
    r, n = meas.r, meas.n
    layers = dict(zip(meas.layer_ids(), meas.layers()))
    Ys = [layers[l] for l in layer_ids]
    dirs = [_directions(model, meas, l, pre) for l, pre in zip(layer_ids, pres)]
    per = [{name: np.empty((n, Y.shape[2])) for name in ("mA", "vA", "mB", "vB", "kM", "ma", "mb")}
           | {"excess": np.empty(n)} for Y in Ys]
    halves, split = [], []
    for sl, Ms in shots.blocks():
        for li, M in enumerate(Ms):
            M, P = np.asarray(M), per[li]
            h = M.shape[1] // 2
            if len(halves) < len(Ms):
                halves.append((slice(0, h), slice(h, 2 * h)))
            # each half widened (exactly) while its statistics are made, then given back
            MB = np.array(M[:, h:2 * h], np.float64)
            P["mB"][sl], P["vB"][sl] = MB.mean(1), MB.var(1, ddof=1)
            del MB
            MA = np.array(M[:, :h], np.float64)
            P["mA"][sl], P["vA"][sl] = MA.mean(1), MA.var(1, ddof=1)
            groups = max(h // r, 1)
            P["kM"][sl] = (np.mean([_kurt(MA[:, g * r:(g + 1) * r]) for g in range(groups)], axis=0) if h >= r
                           else _kurt(MA))
            P["excess"][sl] = _excess(MA, _unit(dirs[li][0][sl]))
            del MA
            if paired:  # the model's shots fed each half of the measured shots (draw j of shot k at j r + k)
                W = np.array(M[:, :2 * h], np.float64).reshape(M.shape[0], -1, r, M.shape[2])
                A = W[:, :, :r // 2].reshape(M.shape[0], -1, M.shape[2])
                P["ma"][sl], k = A.mean(1), A.shape[1]
                del A
                P["mb"][sl] = W[:, :, r // 2:2 * (r // 2)].reshape(M.shape[0], -1, M.shape[2]).mean(1)
                del W
                if len(split) < len(Ms):
                    split.append(k)
            elif len(split) < len(Ms):
                split.append(h)
    out = {k: [] for k in ("Y", "mean_resid", "var_resid", "kurt_resid", "mA", "mB", "vB", "pre", "gain_dir",
                           "slope", "model_terms")}
    for li, (Y, P, pre, (g, sl_)) in enumerate(zip(Ys, per, pres, dirs)):
        h = halves[li][0].stop
        mA, vA, mB, vB = P["mA"], P["vA"], P["mB"], P["vB"]
        md, vd = Y.mean(1), Y.var(1, ddof=1)
        floor = 1e-12 * max(float(np.mean(vB)), 1e-300)
        out["Y"].append(Y)
        out["mean_resid"].append((md - mA) / np.sqrt(vB * (1.0 / r + 1.0 / h) + floor))
        out["var_resid"].append((vd - vA) / (vB + floor))
        out["kurt_resid"].append(_kurt(Y) - P["kM"])
        out["mA"].append(mA)
        out["mB"].append(mB)
        out["vB"].append(vB)
        out["pre"].append(pre)
        out["gain_dir"].append(g)
        out["slope"].append(sl_)
        means = (P["ma"], P["mb"], split[li]) if paired else (mA, mB, h)
        out["model_terms"].append({"half_means": means, "excess": P["excess"]})
    out["MA"] = ModelHalf(shots, [a for a, _ in halves], n)
    out["MB"] = ModelHalf(shots, [b for _, b in halves], n)
    return Residuals(meas, model, tuple(layer_ids), t=meas.t, paired=paired, **out)


def _unit(g):
    """Each input's direction ``g`` (n, d) scaled to unit length."""
    return g / np.sqrt(np.sum(g ** 2, axis=1, keepdims=True) + 1e-300)


def _excess(S, w):
    """Per input: the variance of the shots ``S`` (n, k, d) projected on ``w`` (n, d) beyond the
    sum of the per-neuron variances along it."""
    return np.var(np.einsum("nkd,nd->nk", S, w), axis=1, ddof=1) - np.sum(w ** 2 * S.var(1, ddof=1), -1)


def _shot_source(key, model: Model, meas: Measurement, shots: int | None) -> ModelShots:
    """The model's shots of every measured layer under ``key`` (:func:`model_shots`), held when
    one block of :func:`shot_blocks` holds them, else made a block at a time on each reading."""
    K = default_model_shots(meas.r) if shots is None else int(shots)
    if block_inputs(meas, K) >= meas.n:
        return ModelShots.whole(np.asarray(M) for M in model_shots(key, model, meas, shots))  # float32
    return ModelShots(lambda: ((sl, tuple(np.asarray(M) for M in Ms))
                               for sl, Ms in shot_blocks(key, model, meas, shots)))


def residuals(key, model: Model, meas: Measurement, shots: int | None = None) -> Residuals:
    """The :class:`Residuals` of ``model`` on ``meas``: the model's own shots of every measured
    layer (K = ``shots``, default 4 r), errors of earlier layers propagated."""
    pres = noiseless_pre(model, meas)
    return _residuals_from(meas, model, meas.layer_ids(), _shot_source(named_subkey(key, "residual_shots"), model,
                                                                         meas, shots),
                           [pres[l - 1] for l in meas.layer_ids()])


def one_step_residuals(key, model: Model, meas: Measurement, levels: dict | None = None, draws: int = 4) -> Residuals:
    """The :class:`Residuals` of each layer on its own (taps): the layer's model fed the measured
    layer before, ``draws`` model shots per measured shot, each layer at its noise level
    ``levels[l]`` (default the model's s). Layer l's residuals then say what is wrong *in* layer
    l, not what it inherits."""
    ids = [l for l in meas.layer_ids() if l == 1 or meas.has_taps]
    keys, models = {}, {}
    for l in ids:
        m = model
        if levels and l in levels and "awgn" in model.physics:
            m = Model(model.physics.replace(s=levels[l]), model.params, model.offsets)
        keys[l], models[l] = jax.random.fold_in(named_subkey(key, "one_step_residuals"), l), m
    B = one_step_block_inputs(meas, ids, draws)
    if B >= meas.n:  # float32, read as float64 (ModelHalf)
        shots = ModelShots.whole(np.asarray(one_step_shots(keys[l], models[l], meas, l, draws=draws)) for l in ids)
    else:
        shots = ModelShots(lambda: ((slice(i0, min(i0 + B, meas.n)),
                                     tuple(np.asarray(one_step_rows(keys[l], models[l], meas, l, draws, i0, B))
                                           for l in ids)) for i0 in range(0, meas.n, B)))
    return _residuals_from(meas, model, ids, shots, [one_step_pre(model, meas, l) for l in ids], paired=True)


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

def chi_z(zs) -> float:
    """A chi-square of independent N(0, 1) values on the normal scale (one-sided): exact while
    its tail is representable, then Wilson-Hilferty's cube-root normal (a p-value capped at
    1e-300 would cap every strong chi-square at z = 37 and lose to unbounded statistics)."""
    zs = np.asarray(zs, np.float64)
    zs = zs[np.isfinite(zs)]
    if zs.size == 0:
        return 0.0
    q, k = float(np.sum(zs ** 2)), zs.size
    sf = stats.chi2.sf(q, df=k)
    if sf > 1e-250:
        return float(stats.norm.isf(sf))
    return float(((q / k) ** (1.0 / 3.0) - (1.0 - 2.0 / (9.0 * k))) / np.sqrt(2.0 / (9.0 * k)))


def _design(zpre):
    """Per neuron: the columns [1, z, z^2 - mean, z^3 - fit] of the standardised pre-activation,
    (d, n, 4): a smooth distortion of a neuron's transfer is a function of its z."""
    zc = (zpre - zpre.mean(0)) / (zpre.std(0) + 1e-12)
    sq = zc * zc
    z2 = sq - np.mean(sq, 0)
    z3 = zc * sq - zc * np.mean(sq * sq, 0) / np.maximum(np.mean(sq, 0), 1e-12)
    return np.stack([np.ones_like(zc), zc, z2, z3], axis=-1).transpose(1, 0, 2)


def _profiles(e, X):
    """Per neuron j, OLS of e[:, j] on X[j]: coefficients (d, k) and their z (d, k)."""
    betas, zs = [], []
    for j in range(e.shape[1]):
        beta, *_ = np.linalg.lstsq(X[j], e[:, j], rcond=None)
        resid = e[:, j] - X[j] @ beta
        s2 = float(resid @ resid) / max(e.shape[0] - X.shape[2], 1)
        cov = s2 * np.linalg.pinv(X[j].T @ X[j])
        betas.append(beta)
        zs.append(beta / np.sqrt(np.maximum(np.diag(cov), 1e-300)))
    return np.array(betas), np.array(zs)


def _mixed_signs(zs, z_min: float = 2.0) -> float:
    """How mixed the signs of the significant values are: 1 - |mean sign| over |z| > z_min (1:
    balanced, 0: all one way; 1 when fewer than three are significant)."""
    sig = zs[np.abs(zs) > z_min]
    return 1.0 if sig.size < 3 else float(1.0 - abs(np.mean(np.sign(sig))))


def _half_means(res: Residuals, li: int):
    """``(mean of A, mean of B, shots in each)`` per cell of layer ``li``: the model's halves set
    against the measured shots' first and second halves. One-step shots (draw j of measured shot
    k at j r + k): each data half against the model shots fed with that half's measured inputs
    (else the halves share inputs); otherwise half A's and half B's means. Made with the
    residuals (``res.model_terms``); read from ``res.MA``, ``res.MB`` by a Residuals without them."""
    if res.model_terms is not None:
        return res.model_terms[li]["half_means"]
    if not res.paired:
        return res.mA[li], res.mB[li], half_shots(res.MA, li)
    n, r, d = res.Y[li].shape
    h = r // 2
    M = np.concatenate([res.MA[li], res.MB[li]], axis=1).reshape(n, -1, r, d)
    A = M[:, :, :h].reshape(n, -1, d)
    k, ma = A.shape[1], A.mean(1)
    del A
    return ma, M[:, :, h:2 * h].reshape(n, -1, d).mean(1), k


def _beyond_profiles(res: Residuals, li: int, X, means) -> float:
    """Reproducible mean residual that no per-neuron function of z explains (a linear-map
    error): the two halves of the measured shots give residual means ra, rb against disjoint
    model halves; each is projected off the neuron's profile design; sum of ra . rb over inputs
    and neurons per input, tested over inputs (zero mean under the model: the halves are
    independent; a self-normalised sum would be capped at sqrt(n) and lose to any chi-square)."""
    Y, vB = res.Y[li], res.vB[li]
    h = Y.shape[1] // 2
    ma, mb, k = means  # (_half_means: made once per layer, read by both of its calls here)
    se = np.sqrt(vB * (1.0 / max(h, 1) + 1.0 / k) + 1e-300)
    ra = (Y[:, :h].mean(1) - ma) / se
    rb = (Y[:, h:2 * h].mean(1) - mb) / se
    T = np.zeros(Y.shape[0])
    for j in range(Y.shape[2]):  # off the design's columns: X (X^+ v), never the (n, n) projector
        pinv = np.linalg.pinv(X[j])
        T += (ra[:, j] - X[j] @ (pinv @ ra[:, j])) * (rb[:, j] - X[j] @ (pinv @ rb[:, j]))
    return over_inputs(T)


def _excess_covariance(res: Residuals, li: int) -> np.ndarray:
    """Per input: the variance of the shots projected on the layer's gain direction beyond the
    sum of the per-neuron variances along it (a gain shared by the neurons adds a rank-one
    covariance there), measured minus model (half A), over the model's (half B) variance along it."""
    w = _unit(res.gain_dir[li])
    if res.model_terms is not None:
        model = res.model_terms[li]["excess"]
    else:
        model = np.empty(res.n)
        for sl, (MA,) in half_blocks(res.MA, (li,)):
            model[sl] = _excess(MA, w[sl])
    return (_excess(res.Y[li], w) - model) / (np.sum(w ** 2 * res.vB[li], -1) + 1e-300)


def layer_evidence(res: Residuals) -> list[dict]:
    """Per layer of ``res``: how its residuals depart from the model, each departure a z over the
    layer (N(0, 1) or one-sided chi-square on the normal scale under the model).

    ``offset_z``        per-neuron constant shifts of the mean (chi-square over neurons);
                        ``offset_mixed`` how mixed their signs are (1 - |mean sign|)
    ``bias_z``          per-neuron shifts of the mean along sigma'(z) -- what a shifted bias does
                        (chi-square over neurons; ``bias_mixed`` their signs' mix), and
                        ``bias_rest_z`` the reproducible residual beyond them
    ``profile_z``       per-neuron slope, curvature and cubic term of the mean residual against
                        the pre-activation z (chi-square over neurons): a distorted transfer
    ``common_offset_z``, ``common_slope_z``, ``common_curve_z``
                        the same shared by every neuron of the layer (signed; over inputs), and
                        ``slope_mixed``, ``curve_mixed`` how mixed the per-neuron signs are
    ``structure_z``     reproducible mean residual beyond every per-neuron function of z
    ``var_level_z``     excess variance, ``var_abs_z`` excess variance along |z| (signed)
    ``kurt_z``          excess kurtosis at equal sample size (signed)
    ``corr_z``          excess covariance shared by the neurons (signed)
    ``time_z``          mean residual along acquisition time (signed; files with times)
    """
    out = []
    for li, l in enumerate(res.layer_ids):
        e, v, k, zpre = res.mean_resid[li], res.var_resid[li], res.kurt_resid[li], res.pre[li]
        X = _design(zpre)
        betas, zs = _profiles(e, X)
        zc = X[:, :, 1].T
        absz = np.abs(zc) - np.mean(np.abs(zc), axis=0)
        # per neuron, the mean residual as a multiple of sigma'(z): what a bias offset does
        bias_design = res.slope[li].T[:, :, None]
        bz = _profiles(e, bias_design)[1][:, 0]
        means = _half_means(res, li)
        row = {"layer": int(l), "neurons": int(e.shape[1]),
               "offset_z": chi_z(zs[:, 0]), "offset_mixed": _mixed_signs(zs[:, 0]),
               "bias_z": chi_z(bz), "bias_mixed": _mixed_signs(bz),
               "bias_rest_z": _beyond_profiles(res, li, bias_design, means),
               "profile_z": chi_z(zs[:, 1:].ravel()),
               "slope_mixed": _mixed_signs(zs[:, 1]), "curve_mixed": _mixed_signs(zs[:, 2]),
               "common_offset_z": over_inputs(np.sum(e, axis=1)),
               "common_slope_z": over_inputs(np.sum(e * zc, axis=1)),
               "common_curve_z": over_inputs(np.sum(e * X[:, :, 2].T, axis=1)),
               "structure_z": _beyond_profiles(res, li, X, means),
               "var_level_z": over_inputs(np.sum(v, axis=1)),
               "var_abs_z": over_inputs(np.sum(v * absz, axis=1)),
               "kurt_z": over_inputs(np.sum(k, axis=1)),
               "corr_z": over_inputs(_excess_covariance(res, li)) if e.shape[1] > 1 else 0.0}
        if res.t is not None:
            tc = res.t.mean(1) - res.t.mean()
            row["time_z"] = over_inputs(tc * np.sum(e * np.sign(res.mB[li]), axis=1))
        out.append(row)
    return out


# ---- heatmaps ---------------------------------------------------------------------------------

#: probabilities of the law panel's quantiles (tails included: a law shows there first)
QQ_PROBS = np.concatenate([[0.001, 0.003, 0.01, 0.03], np.linspace(0.05, 0.95, 19), [0.97, 0.99, 0.997, 0.999]])
#: bins of the PIT histograms
PIT_BINS = 10


def _below(Y, M):
    """(n, r, d): per measured shot, how many of the model's shots of its cell lie below it."""
    n, r, d = Y.shape
    below = np.empty(Y.shape)
    chunk = max(1, int(2e7 // max(r * M.shape[1] * d, 1)))
    for c0 in range(0, n, chunk):
        below[c0:c0 + chunk] = np.sum(M[c0:c0 + chunk, None, :, :] < Y[c0:c0 + chunk, :, None, :], axis=2)
    return below


def _pit(key, below, K: int):
    """(n, r, d) randomised PIT of each measured shot among the model's K shots of its cell:
    (number of model shots below it + U) / (K + 1), U ~ Uniform(0, 1) -- exactly uniform under
    the model (the shot's rank among K + 1 exchangeable values). ``below``: :func:`_below`'s
    counts."""
    u = np.array(_random.uniform01(key, below.shape), np.float64)  # jax.random.uniform's numbers, ours to write
    u += below
    u /= K + 1
    return u


def _fisher(S):
    """Per input, the Fisher z of the correlation of each pair of neurons over the shots ``S``
    (n, k, d), and the correlations: ((n, d, d), (n, d, d))."""
    c = S - S.mean(1, keepdims=True)
    C = np.einsum("nki,nkj->nij", c, c)
    sd = np.sqrt(np.maximum(np.einsum("nii->ni", C), 1e-300))
    R = np.clip(C / sd[:, :, None] / sd[:, None, :], -0.999999, 0.999999)
    return np.arctanh(R), R


def _correlation_z(Y, fm, Rm, K: int):
    """(d, d): per pair of neurons, the measured shots' correlation within a cell against the
    model's (Fisher z, each net of its small-sample bias rho / (2 (m - 1)) at its own shot count),
    averaged over inputs and tested over inputs (Student t on the normal scale); 0 on the
    diagonal. ``fm``, ``Rm``: :func:`_fisher` of the model's K shots per cell."""
    fy, _ = _fisher(Y)
    diff = fy - fm - Rm * (1.0 / (2 * (Y.shape[1] - 1)) - 1.0 / (2 * (K - 1)))
    n = diff.shape[0]
    mean, se = diff.mean(0), diff.std(0, ddof=1) / np.sqrt(n)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        t = np.where(se > 0, mean / se, 0.0)
        z = np.sign(t) * stats.norm.isf(stats.t.sf(np.abs(t), df=n - 1))
    z = np.where(np.isfinite(z), z, t)
    np.fill_diagonal(z, 0.0)
    return z


def _pooled_kurtosis(a) -> float:
    """``scipy.stats.kurtosis`` of the 1-D array ``a`` (Fisher's, biased), the same numbers with
    one temporary of ``a``'s size instead of three."""
    mean = np.mean(a, axis=0, keepdims=True)
    s = a - mean
    s *= s
    m2 = np.mean(s, axis=0)
    s *= s
    m4 = np.mean(s, axis=0)
    del s
    with np.errstate(all="ignore"):
        zero = m2 <= (np.finfo(m2.dtype).eps * mean[0]) ** 2
        return float(np.where(zero, np.nan, m4 / m2 ** 2.0)[()] - 3)


def where_it_fails(key, model: Model, meas: Measurement, bins: int = 6, shots: int | None = None,
                   res: Residuals | None = None) -> dict:
    """Per-cell standardised statistics, binned over the model's noiseless pre-activation (rows
    ``layer:neuron``, a bin holds ``sum z / sqrt(count)``, N(0, 1) under the model), the worst
    cells, and per measured layer the calibration of the model's law of the shots.

    The bins are the same for every row, ``edges`` (bins + 1,): quantiles of every row's
    pre-activations pooled, so each bin is a range of the pre-activation a figure can name (a
    neuron whose inputs never reach a bin leaves it empty, NaN).

    Returns
    -------
    dict with ``rows`` (list of "layer:neuron"), ``edges``, ``maps`` ({statistic: (rows, bins)
    array}), ``worst`` (list of {layer, neuron, input, statistic, z}, worst first), and per layer
    (``{layer: ...}``): ``pit`` (:data:`PIT_BINS` counts of the measured shots' randomised PIT
    among the model's shots of their cell, uniform under the model) with ``pit_cells`` (cells
    behind them), ``correlation`` ((d, d) z of the measured correlation between two neurons
    within a cell against the model's, over inputs; layers of two or more neurons) and ``qq``
    (quantiles at :data:`QQ_PROBS` of the shots standardised by the model's cell mean and
    variance, measured and the model's own, and both pooled excess kurtoses)
    """
    res = res if res is not None else residuals(key, model, meas, shots)
    r = meas.r
    names = ["mean_z", "log_var_ratio", "excess_kurtosis"] + (["time_trend"] if meas.t is not None else [])
    rows, maps, worst = [], {k: [] for k in names}, []
    pooled = np.concatenate([np.ravel(p) for p in res.pre])
    edges = np.quantile(pooled, np.linspace(0, 1, bins + 1))
    pit, pit_cells, corr, qq = {}, {}, {}, {}
    k_pit = named_subkey(key, "pit")
    for li, l in enumerate(res.layer_ids):
        Y, K2 = res.Y[li], half_shots(res.MB, li)
        with np.errstate(divide="ignore", invalid="ignore"):
            lvr = np.log(np.maximum(Y.var(1, ddof=1), 1e-300) / np.maximum(res.vB[li], 1e-300))
        lvr -= log_variance_bias(r - 1) - log_variance_bias(K2 - 1)  # r against K2 shots: mean 0 under the model
        cell = {"mean_z": res.mean_resid[li],
                "log_var_ratio": lvr / np.sqrt(2 / (r - 1) + 2 / (K2 - 1)),
                "excess_kurtosis": res.kurt_resid[li] / np.sqrt(24 / r + 24 / r)}
        if meas.t is not None:
            resid = (Y - res.mB[li][:, None, :]) / np.sqrt(res.vB[li][:, None, :] + 1e-300)
            tc = meas.t - meas.t.mean()
            cell["time_trend"] = np.einsum("nr,nrd->nd", tc, resid) / np.sqrt(np.sum(tc ** 2, 1) + 1e-300)[:, None]
        pre = res.pre[li]
        idx = np.clip(np.searchsorted(edges, pre, side="right") - 1, 0, bins - 1)
        for j in range(Y.shape[2]):
            rows.append(f"{l}:{j}")
            for name in names:
                v = cell[name][:, j]
                row = np.full(bins, np.nan)
                for b_ in range(bins):
                    sel = idx[:, j] == b_
                    if sel.any():
                        row[b_] = v[sel].sum() / np.sqrt(sel.sum())
                maps[name].append(row)
        # kurtosis of a few dozen shots is far from normal in its tails: shown, not ranked
        for name in ("mean_z", "log_var_ratio"):
            v = cell[name]
            for f in np.argsort(-np.abs(np.nan_to_num(v)), axis=None)[:10]:
                i, j = np.unravel_index(f, v.shape)
                worst.append({"layer": int(l), "neuron": int(j), "input": int(i), "statistic": name, "z": float(v[i, j])})
        # the law of the shots: PIT, correlations between neurons, quantiles of standardised shots
        # (the model's shots read a block of inputs at a time)
        below, fm, Rm = np.empty(Y.shape), None, None
        with_corr = Y.shape[2] > 1 and r >= 4
        if with_corr:
            fm, Rm = np.empty((Y.shape[0], Y.shape[2], Y.shape[2])), np.empty((Y.shape[0], Y.shape[2], Y.shape[2]))
        for sl, (MB,) in half_blocks(res.MB, (li,)):
            below[sl] = _below(Y[sl], MB)
            if with_corr:
                fm[sl], Rm[sl] = _fisher(MB)
        del MB
        u = _pit(jax.random.fold_in(k_pit, l), below, K2)
        del below
        pit[int(l)] = np.histogram(u, bins=PIT_BINS, range=(0.0, 1.0))[0]
        del u
        pit_cells[int(l)] = int(Y.shape[0] * Y.shape[2])
        if with_corr:
            corr[int(l)] = _correlation_z(Y, fm, Rm, K2)
        del fm, Rm
        # the quantiles of the standardised shots: the measured ones, then the model's (each
        # with its kurtosis first: the quantiles reorder the array they are given)
        sd = np.sqrt(res.vB[li] + 1e-300)[:, None, :]
        ys = Y - res.mB[li][:, None, :]
        ys /= sd
        ys = np.ravel(ys)
        kurt_y = _pooled_kurtosis(ys)
        q_y = np.quantile(ys, QQ_PROBS, overwrite_input=True)
        del ys
        ms = None
        for sl, (MA,) in half_blocks(res.MA, (li,)):  # standardised as read (into an array of ours)
            if ms is None:
                ms = np.empty((Y.shape[0],) + MA.shape[1:])
            ms[sl] = MA
            ms[sl] -= res.mB[li][sl, None, :]
            ms[sl] /= sd[sl]
        del MA
        ms = np.ravel(ms)
        kurt_m = _pooled_kurtosis(ms)
        qq[int(l)] = {"measured": q_y, "model": np.quantile(ms, QQ_PROBS, overwrite_input=True),
                      "kurtosis_measured": kurt_y, "kurtosis_model": kurt_m}
        del ms
    worst.sort(key=lambda w: -abs(w["z"]))
    return {"rows": rows, "edges": edges, "maps": {k: np.array(v) for k, v in maps.items()}, "worst": worst,
            "pit": pit, "pit_cells": pit_cells, "correlation": corr, "qq": qq}
