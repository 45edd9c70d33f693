"""Stage 4 of the lab: one model against one measurement -- a discrepancy, its noise floor, a p-value.

:func:`compare` scores every cell's channels (:mod:`._channels`) with the discrepancy test
(:mod:`._qtest`). :func:`one_step_check` localises: each measured layer's model fed with the
*measured* output of the layer before, same shot, so a layer is judged on its own physics
and not on the errors of the layers before it. Measured calibration in
``studies/calibrate.py`` (false alarms at p < 0.01 over null data sets).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import numpy as np
from scipy import optimize, stats

from .._errors import GiftInputError
from .._measurement import Measurement
from .._model import named_subkey
from .._process import release_freed_memory
from ..chips import simulate_measurement
from ._channels import (
    Reference,
    cell_statistic,
    channel_values,
    combine,
    paired_moment_channels,
    reference,
)
from ._qtest import log_variance_bias, over_inputs, q_test, replicate_null
from ._channels import _input_chunk, _variance_floor
from ._shots import Model, model_shots, one_step_block_inputs, one_step_rows, one_step_shots, to32


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
    channel_values : (n, L' C) the per-input channel values behind ``discrepancy`` (the paired
        standard error of a difference of two models' discrepancies on the same inputs,
        :func:`discrepancy_difference`), or None
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
    channel_values: np.ndarray | None = dataclasses.field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict:
        extra = {} if not self.replicates else {"net_discrepancy": self.net_discrepancy,
                                                 "refit_null_replicates": self.replicates}
        return {**extra, "discrepancy": self.discrepancy, "se": self.se, "noise_floor": self.noise_floor,
                "floor_se": self.floor_se, "p_value": self.p_value,
                "per_layer": {f"layer{l}": float(v) for l, v in zip(self.layer_ids, self.per_layer)},
                "channel_z": {f"layer{l}": {c: float(z) for c, z in zip(self.channels, row)}
                              for l, row in zip(self.layer_ids, self.channel_z)}}


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
    need = model.physics.needs_times()
    if need and meas.t is None:
        raise GiftInputError(f"model {model.describe()}: {need[0]} acts through the acquisition times t, and the "
                             f"measurement has none")
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
    T, cells = combine(C, ref.weights)
    return Comparison(discrepancy=Q, se=null_sd, noise_floor=ref.noise_floor, floor_se=ref.floor_se, p_value=p,
                      per_input=T, per_layer=np.sum(np.maximum(zl, 0.0) ** 2, axis=1), layer_ids=meas.layer_ids(),
                      cells=cells, channel_z=zl, channels=ref.channels, net_discrepancy=net, replicates=B,
                      channel_values=C.reshape(meas.n, -1))


#: bootstrap replicates of :func:`discrepancy_difference`
DIFFERENCE_REPLICATES = 1000


def _q_of(T):
    """Q of :func:`~gift_theory.lab._qtest.q_test` for a stack of channel matrices (B, n, C)."""
    n = T.shape[1]
    mean, sd = T.mean(1), T.std(1, ddof=1)
    ok = sd > 1e-12 * (np.abs(mean) + 1e-300)
    t = np.where(ok, mean / np.where(ok, sd, 1.0) * np.sqrt(n), 0.0)
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        z = stats.norm.isf(stats.t.sf(t, df=n - 1))
    z = np.where(np.isfinite(z), z, t)
    return np.sum(np.maximum(z, 0.0) ** 2, axis=1)


def discrepancy_difference(a: Comparison, b: Comparison, replicates: int = DIFFERENCE_REPLICATES,
                           seed: int = 0) -> tuple[float, float]:
    """``(delta, se)``: a's discrepancy minus b's on the same inputs and its standard error, by the
    paired bootstrap over inputs (inputs are independent; both models' channel values of an input
    are resampled together, so what the two share cancels, as in ArviZ's ``compare``). ``se`` is
    NaN when either comparison carries no channel values or the inputs differ."""
    delta = float(a.discrepancy - b.discrepancy)
    Ta, Tb = getattr(a, "channel_values", None), getattr(b, "channel_values", None)
    if Ta is None or Tb is None or Ta.shape[0] != Tb.shape[0]:
        return delta, float("nan")
    if Ta is Tb:
        return delta, 0.0
    n = Ta.shape[0]
    idx = np.random.default_rng(seed).integers(0, n, size=(replicates, n))
    # the resampled channel matrices a few replicates at a time: all 1000 at once were 0.4 GB on a
    # 50 MB file's held-out half (each Q depends on its own replicate only: the same numbers)
    step = max(1, int(BOOTSTRAP_BYTES // max(8 * n * Ta.shape[1], 1)))
    d = np.concatenate([_q_of(Ta[idx[b:b + step]]) - _q_of(Tb[idx[b:b + step]]) for b in range(0, replicates, step)])
    return delta, float(np.std(d, ddof=1))


#: bytes of one model's resampled channel matrices :func:`discrepancy_difference` holds at once
BOOTSTRAP_BYTES = 16 << 20


def one_step_blocks(key, model: Model, meas: Measurement, layer: int, draws: int = 0):
    """:func:`~._shots.one_step_shots` of layer ``layer`` a block of inputs at a time: yields
    ``(slice of inputs, their shots)`` (float32 numpy, bit for bit the whole array's rows), one
    block when the layer's shots fit in :data:`~._shots.SHOT_BLOCK_BYTES`."""
    B = one_step_block_inputs(meas, (layer,), draws)
    if B >= meas.n:
        yield slice(0, meas.n), np.asarray(one_step_shots(key, model, meas, layer, draws=draws))
        return
    for i0 in range(0, meas.n, B):
        yield slice(i0, min(i0 + B, meas.n)), np.asarray(one_step_rows(key, model, meas, layer, draws, i0, B))


def one_step_cells(key, model: Model, meas: Measurement, layer: int, f, draws: int = 0) -> np.ndarray:
    """``f(rows, M)`` of each block of layer ``layer``'s one-step shots (:func:`one_step_blocks`),
    put together over the inputs: a statistic of each input's shots (a (b, ...) array for the
    block's b inputs) with one block of shots in memory at a time."""
    out = None
    for sl, M in one_step_blocks(key, model, meas, layer, draws):
        v = np.asarray(f(sl, M))
        if out is None:
            out = np.empty((meas.n,) + v.shape[1:], v.dtype)
        out[sl] = v
        del M
    return out


def _cell_var(sl, M):
    """Each cell's variance (ddof 1) of a block of shots, in float64."""
    return np.var(np.asarray(M, np.float64), axis=1, ddof=1)


def layer_level(key, model: Model, meas: Measurement, layer: int, xtol: float = 1e-4) -> float:
    """The additive noise level s at which layer ``layer``'s one-step shots are as variable as the
    measured ones (mean log variance over the layer's cells, both from r shots, so their
    small-sample bias is the same): the root in log s over [s / 20, 20 s] (Brent's method to
    ``xtol`` in log s, 0.01 % of s; the gap grows with s), or the end the gap does not change
    sign beyond. The search starts from the model's s, or -- a model without additive noise --
    from the layer's own spread: no fixed floor (at s = 1e-6 a floor of 1e-4 set every layer's
    level 5e-6 and failed each one at z = 89-328)."""
    li = meas.layer_ids().index(layer)
    v = np.var(meas.layers()[li], axis=1, ddof=1)
    tiny = 1e-12 * max(float(np.mean(v)), np.finfo(np.float64).tiny)  # log of a cell with no spread: bounded
    target = float(np.mean(np.log(v + tiny)))
    s0 = float(model.physics.s)
    if not s0 > 0:
        s0 = float(np.sqrt(np.mean(v) / 2.0)) or 1.0

    @functools.lru_cache(maxsize=None)  # brentq evaluates the ends again
    def gap(log_s):
        m = Model(model.physics.replace(s=float(np.exp(log_s))), model.params, model.offsets)
        return float(np.mean(np.log(one_step_cells(key, m, meas, layer, _cell_var) + tiny))) - target

    lo, hi = float(np.log(s0 / 20.0)), float(np.log(s0 * 20.0))
    if gap(lo) >= 0:
        return float(np.exp(lo))
    if gap(hi) <= 0:
        return float(np.exp(hi))
    return float(np.exp(optimize.brentq(gap, lo, hi, xtol=xtol)))


#: degree of the polynomial each neuron's measured transfer is read with (:func:`transfer_level`)
TRANSFER_DEGREE = 3
#: a failing layer's level is read through its measured transfer only when that transfer changes
#: the model shots' log variance by more than this, rms over the cells (a factor 1.65 in
#: variance): a transfer near the identity is the polynomial's own error (rms 0.06-0.22 on the
#: layers of shot, multiplicative and Laplace files, where it moved the level by up to 13 %;
#: 1.2 on a square-law detector)
TRANSFER_MIN_LOG_VAR = 0.5


def _transfer(Ybar, Mbar, degree: int = TRANSFER_DEGREE):
    """Per neuron the polynomial (least squares over the inputs) mapping the model's cell means
    ``Mbar`` (n, d) to the measured ones ``Ybar``: a callable applied to model shots (..., d)."""
    d = Ybar.shape[1]
    coefs = []
    for j in range(d):
        x = Mbar[:, j]
        scale = max(float(np.std(x)), 1e-12)
        c = np.polynomial.polynomial.polyfit((x - x.mean()) / scale, Ybar[:, j], min(degree, max(len(x) - 2, 1)))
        coefs.append((x.mean(), scale, c))

    def apply(M):
        return np.stack([np.polynomial.polynomial.polyval((M[..., j] - m0) / sc, c)
                         for j, (m0, sc, c) in enumerate(coefs)], axis=-1)
    return apply


def transfer_level(key, model: Model, meas: Measurement, layer: int, start: float,
                   xtol: float = 1e-4) -> tuple[float, float] | None:
    """``(s, level_z)``: the additive noise level of layer ``layer`` read through its *measured*
    transfer, and how far the layer's variability is from the joint level's through it; None
    when the transfer changes the cells' log variance by less than :data:`TRANSFER_MIN_LOG_VAR`
    (rms over the cells).

    Each neuron's transfer is the polynomial (:data:`TRANSFER_DEGREE`) from the model's cell means
    to the measured ones; the model's one-step shots are passed through it before their
    variances meet the measured ones (as in :func:`layer_level`, mean log variance of r shots).
    Where the readout is not the model's -- a square-law detector y = beta v^2 -- the measured
    variance is the noise's times the transfer's slope squared (4 beta^2 v^2 s^2): read as is, the
    output's level came out 0.005 on a chip at s = 0.1 whose hidden layers read 0.1; through the
    transfer it is the noise's own. ``start``: the level the transfer is fitted at, the root
    searched over [start / 20, 20 start] (the joint level: the level read without the transfer
    can sit at its own bracket's end)."""
    li = meas.layer_ids().index(layer)
    Y = np.asarray(meas.layers()[li], np.float64)
    target = float(np.mean(np.log(np.var(Y, axis=1, ddof=1) + 1e-30)))

    def cells(s, g):
        m = Model(model.physics.replace(s=float(s)), model.params, model.offsets)
        return one_step_cells(key, m, meas, layer, lambda sl, M: g(np.asarray(M, np.float64)))

    def var(M):
        return np.var(M, axis=1, ddof=1)

    f = _transfer(Y.mean(1), cells(start, lambda M: M.mean(1)))
    both = cells(start, lambda M: np.stack([var(f(M)), var(M)]).swapaxes(0, 1))  # (n, 2, d)
    with np.errstate(divide="ignore"):
        bend = float(np.sqrt(np.mean((np.log(both[:, 0] + 1e-30) - np.log(both[:, 1] + 1e-30)) ** 2)))
    if bend < TRANSFER_MIN_LOG_VAR:
        return None

    @functools.lru_cache(maxsize=None)
    def gap(log_s):
        return float(np.mean(np.log(cells(np.exp(log_s), lambda M: var(f(M))) + 1e-30))) - target

    lo, hi = float(np.log(start / 20.0)), float(np.log(start * 20.0))
    if gap(lo) >= 0:
        level = float(np.exp(lo))
    elif gap(hi) <= 0:
        level = float(np.exp(hi))
    else:
        level = float(np.exp(optimize.brentq(gap, lo, hi, xtol=xtol)))
    joint = np.mean(np.log(np.var(Y, axis=1, ddof=1) + 1e-30)
                    - np.log(cells(max(float(model.physics.s), 1e-4), lambda M: var(f(M))) + 1e-30), 1)
    return level, over_inputs(joint)


def one_step_check(key, model: Model, meas: Measurement, ref: Reference | None = None, *,
                   own_level: bool = True) -> list[dict]:
    """Per measured layer: the one-step discrepancy (the layer's model fed the measured previous
    layer, same shot) -- the Q-test of :mod:`._qtest` on the cells' channels (the energy ones,
    and the moment ones when r >= 8) -- its sd under the model, z and p-value.

    own_level : give each layer the noise level that matches its own measured variability
        (:func:`layer_level`, reported as ``s``), so that a misfit elsewhere -- which inflates
        the jointly fitted s -- does not make a healthy layer fail on its variance alone; a
        layer fails on the shape of its response and noise, not on a level another layer set.

    A layer that fails its check (at 0.01, Bonferroni over the layers checked) and whose measured
    transfer bends the model's variance has its level read through that transfer instead
    (:func:`transfer_level`; ``"s_through_transfer": true``): its response is not the model's,
    and a readout that bends it scales its variance with the slope squared.

    Without taps only layer 1 can be fed (when the network has one layer, that is the
    output); deeper layers need the taps.
    """
    if ref is None:
        ref = reference(named_subkey(key, "floor"), meas)
    rows = []
    checked = len([l for l in meas.layer_ids() if meas.taps is not None or l == 1])
    for li, (l, Y) in enumerate(zip(meas.layer_ids(), meas.layers())):
        if meas.taps is None and l > 1:
            continue
        k_l = jax.random.fold_in(key, l)
        m, level, level_z = model, float(model.physics.s), 0.0
        if own_level and "awgn" in model.physics:
            # how far the layer's variability is from the joint level's (log variances of r shots
            # on both sides: the same small-sample bias), then the layer at its own level
            vy = np.var(Y, axis=1, ddof=1)
            tiny = 1e-12 * max(float(np.mean(vy)), np.finfo(np.float64).tiny)
            gap = np.mean(np.log(vy + tiny) - np.log(one_step_cells(k_l, model, meas, l, _cell_var) + tiny), 1)
            level_z = over_inputs(gap)
            level = layer_level(k_l, model, meas, l)
            m = Model(model.physics.replace(s=level), model.params, model.offsets)
        Y32, moments = np.asarray(to32(Y)), len(ref.channels) > 2
        eps = _variance_floor(np.asarray(Y, np.float64)) if moments else None
        chunk = _input_chunk(meas.n, meas.r, meas.r, Y.shape[2])  # every block in the whole array's program

        def channels(sl, M):
            blocked = sl.stop - sl.start < meas.n
            C = cell_statistic(M, Y32[sl], paired=True, scales=ref.scales[li], chunk=chunk if blocked else None)
            if moments:
                C = np.concatenate([C, paired_moment_channels(np.asarray(M, np.float64), Y[sl], ref.split[sl], eps)],
                                   axis=1)
            return C
        C = one_step_cells(k_l, m, meas, l, channels)
        Q, p, null_mean, null_sd, _ = q_test(C)
        row = {"layer": l, "discrepancy": Q, "se": null_sd, "z": (Q - null_mean) / null_sd if null_sd > 0
               else float("nan"), "p_value": p, "s": level, "level_z": level_z}
        if own_level and "awgn" in model.physics and p < 0.01 / max(checked, 1):
            through = transfer_level(k_l, model, meas, l, max(float(model.physics.s), 1e-4))
            if through is not None:
                row["s"], row["level_z"] = through
                row["s_through_transfer"] = True
        rows.append(row)
    return rows


def failing_layers(rows, alpha: float = 0.01) -> list[int]:
    """Layers whose one-step check fails at ``alpha`` with Bonferroni over the layers checked."""
    if not rows:
        return []
    return sorted(int(r["layer"]) for r in rows if r["p_value"] < alpha / len(rows))


@dataclasses.dataclass(frozen=True)
class Moments:
    """Per measured layer, each neuron's mean and variance over shots, measured and the model's
    (the numbers of a posterior-predictive check; :func:`gift_theory.lab._figures.moments_figure`).

    layer_ids : the 1-based layer of each entry below
    mean, var : lists of (n, d_l): the measured shots' mean and variance (ddof 1) per input and neuron
    model_mean, model_var : lists of (n, d_l): the same of K model shots at the same inputs
    r, K : measured and model shots per input (they set the error bars)
    label : the model's name
    """

    layer_ids: tuple
    mean: list
    var: list
    model_mean: list
    model_var: list
    r: int
    K: int
    label: str

    def mean_z(self, li: int) -> np.ndarray:
        """(n, d) standardised mean residual, N(0, 1) per cell under the model (shot-count errors)."""
        se2 = self.var[li] / self.r + self.model_var[li] / self.K
        return (self.mean[li] - self.model_mean[li]) / np.sqrt(np.maximum(se2, 1e-300))

    def log_var_ratio(self, li: int) -> tuple[np.ndarray, float]:
        """(n, d) log(measured / model variance), net of its small-sample bias (r against K shots,
        :func:`~._qtest.log_variance_bias`: mean 0 under the model), and its standard deviation
        under the model (sqrt(2/(r-1) + 2/(K-1)), Gaussian shots)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            lr = np.log(np.maximum(self.var[li], 1e-300) / np.maximum(self.model_var[li], 1e-300))
        lr -= log_variance_bias(self.r - 1) - log_variance_bias(self.K - 1)
        return lr, float(np.sqrt(2.0 / (self.r - 1) + 2.0 / (self.K - 1)))


@dataclasses.dataclass(frozen=True)
class PredictiveShots:
    """The measured shots and a model's own shots at the same inputs, per measured layer (the
    numbers of a posterior-predictive overlay, :func:`gift_theory.lab._figures.ppc_figure`).

    layer_ids : the 1-based layer of each entry
    measured : lists of (n, r, d_l); model : lists of (n, K, d_l)
    label : the model's name
    """

    layer_ids: tuple
    measured: list
    model: list
    label: str

    @property
    def r(self) -> int:
        return int(next(Y for Y in self.measured if Y is not None).shape[1])  # a figure's copy holds one layer

    def moments(self) -> "Moments":
        """The per-neuron means and variances of these shots (:class:`Moments`)."""
        return Moments(layer_ids=self.layer_ids, mean=[Y.mean(1) for Y in self.measured],
                       var=[Y.var(1, ddof=1) for Y in self.measured], model_mean=[M.mean(1) for M in self.model],
                       model_var=[M.var(1, ddof=1) for M in self.model], r=self.r, K=int(self.model[0].shape[1]),
                       label=self.label)


def predictive_shots(key, model: Model, meas: Measurement, *, shots: int | None = None,
                     label: str | None = None) -> PredictiveShots:
    """The measured shots and K = ``shots`` (default 4 r, at least 16) of the model's at every
    input of ``meas`` (the draws of :func:`predictive_moments` for the same key)."""
    K = max(4 * meas.r, 16) if shots is None else int(shots)
    ms = [np.asarray(M, np.float64) for M in model_shots(key, model, meas, K)]
    return PredictiveShots(layer_ids=tuple(meas.layer_ids()), measured=list(meas.layers()),
                           model=ms, label=label or " + ".join(model.effects))


def predictive_moments(key, model: Model, meas: Measurement, *, shots: int | None = None,
                       label: str | None = None) -> Moments:
    """The measured and the model's per-neuron mean and variance at every input of ``meas``.

    Parameters
    ----------
    key : PRNG key of the model's shots
    model : Model
    meas : Measurement (use the held-out inputs for a fitted model)
    shots : model shots per input K (default 4 r, at least 16)
    label : the model's name in the figures (default: its effects joined by " + ")
    """
    return predictive_shots(key, model, meas, shots=shots, label=label).moments()


# ---- power: what a "consistent" verdict can and cannot rule out on this file ---------------------

def _power_p(key, model: Model, big: Measurement, n: int) -> np.ndarray:
    """The p-values of :func:`compare`'s test of ``model`` on the B = big.n / n files of n inputs
    that ``big`` holds one after another."""
    k_ref, k_model = jax.random.split(key)
    ref = reference(k_ref, big)
    C = channel_values(k_model, model, big, ref)
    return np.array([q_test(C[g * n:(g + 1) * n].reshape(n, -1))[1] for g in range(big.n // n)])


def _rate(p, alpha: float) -> tuple[float, float]:
    """The rejection rate of p-values ``p`` at ``alpha`` and its binomial standard error."""
    B = len(p)
    rate = float(np.mean(p < alpha))
    return rate, float(np.sqrt(max(rate * (1 - rate), 1.0 / B) / B))


def power_of(key, model: Model, meas: Measurement, *, alpha: float = 0.01, replicates: int = 20) -> list[dict]:
    """The power of :func:`compare`'s test of ``model`` against chips that differ from it by one
    effect, on files of this file's size: its inputs, shot count r, and taps or not.

    ``replicates`` files are simulated at the file's inputs with the file's weights under each
    probe chip, all in one batch, and scored against ``model`` by the same channels and Q test as
    :func:`compare` (the model as given: not refitted on each file). The power is the fraction
    rejected at ``alpha``, with its binomial standard error. Probes (on top of the model's own
    physics -- the awgn baseline, or a fitted model -- at its own noise level s):

    ``noise_law``
        the Laplace law at the same s (the law changed at equal variance); not probed when the
        model's law is already not Gaussian;
    ``input_dependent_noise``
        shot noise carrying half the output variance averaged over the inputs, awgn s / sqrt(2)
        the other half (q from the model's shots): the same mean variance as the model, growing
        with the signal -- what is left for the test once the noise level is fitted; not probed
        when the model has shot noise already.

    For a file without taps, each figure is also computed as if the hidden layers were tapped
    (``power_with_taps``: the same simulated files, hidden layers kept). The probes run in the
    lab's threads (:func:`~._budget.map_in_threads`), each keyed by its name alone: the same
    numbers for any number of threads.

    Returns
    -------
    list of dict: {"mechanism", "probe", "power", "se", "power_with_taps" (None with taps),
    "replicates", "n", "r", "taps", "layers", "probe_params"}; empty for a model without awgn,
    one that already has both probes' physics, or one whose physics depends on the acquisition
    time (the simulated files here carry the file's times only as labels: the probe chips would
    not drift as the model does).
    """
    phys = model.physics
    if "awgn" not in phys.names or phys.needs_times():
        return []
    s = float(phys.s)
    Physics = type(phys)
    probes = []
    if phys.law == "gaussian":
        probes.append(("noise_law", "laplace", phys.with_effect("laplace")))
    if "shot" not in phys.names:
        # shot noise alone at a trial q: the share of the output variance it carries scales with q
        q0 = s * s / max(float(np.median(np.abs(meas.y))), 1e-12)
        k_v = named_subkey(key, "power_variance")
        v_model = float(np.mean(np.var(np.asarray(model_shots(k_v, model, meas, 2 * meas.r)[-1]), axis=1)))
        v_shot = float(np.mean(np.var(np.asarray(model_shots(
            k_v, Model(Physics.parse(["awgn=1e-9", f"shot={q0}"]), model.weights(meas)), meas, 2 * meas.r)[-1]),
            axis=1)))
        q = q0 * 0.5 * v_model / max(v_shot, 1e-300)
        probes.append(("input_dependent_noise", "shot", phys.replace(s=s / np.sqrt(2.0)).with_effect("shot", q=q)))
    params = model.weights(meas)
    hidden = len(meas.params) > 1
    common = {"replicates": replicates, "n": meas.n, "r": meas.r, "taps": meas.has_taps,
              "layers": list(meas.layer_ids())}
    # the replicate files in batches of at most POWER_BYTES (one batch for a small file; a 50 MB
    # file's 20 replicates at once were 1 GB of shots, its batches of 4 some 0.8 GB)
    per_file = 8 * meas.n * meas.r * (sum(meas.arch.widths[1:]) + meas.arch.widths[0])
    batch = int(max(1, min(replicates, POWER_BYTES // max(per_file, 1))))

    def probe(mech, name, phys):
        k = named_subkey(key, f"power_{name}")
        ps, pts = [], []
        for b0 in range(0, replicates, batch):
            kb = k if batch >= replicates else jax.random.fold_in(k, b0)
            nb = min(batch, replicates - b0)
            big = simulate_measurement(named_subkey(kb, "files"), params, np.tile(meas.x, (nb, 1)), phys,
                                       shots=meas.r, activation=meas.activation, taps=hidden)
            if meas.t is not None:
                big = dataclasses.replace(big, t=np.tile(meas.t, (nb, 1)))
            seen = big if meas.has_taps else dataclasses.replace(big, taps=None)
            ps.append(_power_p(named_subkey(kb, "score"), model, seen, meas.n))
            if not meas.has_taps and hidden:
                pts.append(_power_p(named_subkey(kb, "score"), model, big, meas.n))
            del big, seen
            release_freed_memory()  # the batch's files and their scoring, not kept for the next
        p, se = _rate(np.concatenate(ps), alpha)
        pt = _rate(np.concatenate(pts), alpha)[0] if pts else None
        return {"mechanism": mech, "probe": name, "power": p, "se": se, "power_with_taps": pt,
                "probe_params": phys.params_json(), **common}

    # the probes in the lab's threads (each keyed by its name alone: the same numbers for any number)
    from ._budget import default_workers, map_in_threads

    return map_in_threads(lambda pr: probe(*pr), probes, default_workers(meas))


#: bytes of simulated replicate files :func:`power_of` holds at once (their scoring holds some six
#: times that: the model's 4 r shots per input in float32, their draws, the channels' chunks)
POWER_BYTES = 32 << 20


def power_notes(power: list[dict], verdict_passes: bool, threshold: float = 0.8) -> list[str]:
    """Plain sentences, next to a verdict, for the classes :func:`power_of` finds the test weak on
    (power below ``threshold``); empty when it sees them all."""
    notes = []
    lead = "'consistent' does not rule out" if verdict_passes else "this test is weak on"
    what = {"noise_law": "a noise law changed at equal variance (Laplace at the same s)",
            "input_dependent_noise": "input-dependent noise (shot noise carrying half the output variance)"}
    for p in power:
        if p["power"] >= threshold:
            continue
        size = f"{p['n']} inputs x {p['r']} shots, " + ("with taps" if p["taps"] else "outputs only")
        taps = ("" if p["power_with_taps"] is None else
                f"; with taps on the hidden layers: {p['power_with_taps']:.2f}")
        notes.append(f"power: {lead} {what.get(p['mechanism'], p['mechanism'])}: on files of this size ({size}) "
                     f"the test rejects it in {p['power']:.2f} +- {p['se']:.2f} of {p['replicates']} simulated "
                     f"files{taps}")
    return notes
