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
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .._measurement import Measurement
from .._model import named_subkey
from ._channels import (
    Reference,
    cell_statistic,
    channel_values,
    combine,
    paired_moment_channels,
    reference,
)
from ._qtest import over_inputs, q_test, replicate_null
from ._shots import Model, one_step_shots


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
    T, cells = combine(C, ref.weights)
    return Comparison(discrepancy=Q, se=null_sd, noise_floor=ref.noise_floor, floor_se=ref.floor_se, p_value=p,
                      per_input=T, per_layer=np.sum(np.maximum(zl, 0.0) ** 2, axis=1), layer_ids=meas.layer_ids(),
                      cells=cells, channel_z=zl, channels=ref.channels, net_discrepancy=net, replicates=B)


def layer_level(key, model: Model, meas: Measurement, layer: int, xtol: float = 1e-4) -> float:
    """The additive noise level s at which layer ``layer``'s one-step shots are as variable as the
    measured ones (mean log variance over the layer's cells, both from r shots, so their
    small-sample bias is the same): the root in log s over [s / 20, 20 s] (Brent's method to
    ``xtol`` in log s, 0.01 % of s; the gap grows with s), or the end the gap does not change
    sign beyond."""
    li = meas.layer_ids().index(layer)
    target = float(np.mean(np.log(np.var(meas.layers()[li], axis=1, ddof=1) + 1e-30)))
    s0 = max(float(model.physics.s), 1e-4)

    @functools.lru_cache(maxsize=None)  # brentq evaluates the ends again
    def gap(log_s):
        m = Model(model.physics.replace(s=float(np.exp(log_s))), model.params, model.offsets)
        M = np.asarray(one_step_shots(key, m, meas, layer), np.float64)
        return float(np.mean(np.log(np.var(M, axis=1, ddof=1) + 1e-30))) - target

    lo, hi = float(np.log(s0 / 20.0)), float(np.log(s0 * 20.0))
    if gap(lo) >= 0:
        return float(np.exp(lo))
    if gap(hi) <= 0:
        return float(np.exp(hi))
    return float(np.exp(optimize.brentq(gap, lo, hi, xtol=xtol)))


def one_step_check(key, model: Model, meas: Measurement, ref: Reference | None = None, *,
                   own_level: bool = True) -> list[dict]:
    """Per measured layer: the one-step discrepancy (the layer's model fed the measured previous
    layer, same shot) -- the Q-test of :mod:`._qtest` on the cells' channels (the energy ones,
    and the moment ones when r >= 8) -- its sd under the model, z and p-value.

    own_level : give each layer the noise level that matches its own measured variability
        (:func:`layer_level`, reported as ``s``), so that a misfit elsewhere -- which inflates
        the jointly fitted s -- does not make a healthy layer fail on its variance alone; a
        layer fails on the shape of its response and noise, not on a level another layer set.

    Without taps only layer 1 can be fed (when the network has one layer, that is the
    output); deeper layers need the taps.
    """
    if ref is None:
        ref = reference(named_subkey(key, "floor"), meas)
    rows = []
    for li, (l, Y) in enumerate(zip(meas.layer_ids(), meas.layers())):
        if meas.taps is None and l > 1:
            continue
        k_l = jax.random.fold_in(key, l)
        m, level, level_z = model, float(model.physics.s), 0.0
        if own_level and "awgn" in model.physics:
            # how far the layer's variability is from the joint level's (log variances of r shots
            # on both sides: the same small-sample bias), then the layer at its own level
            M0 = np.asarray(one_step_shots(k_l, model, meas, l), np.float64)
            gap = np.mean(np.log(np.var(Y, axis=1, ddof=1) + 1e-30) - np.log(np.var(M0, axis=1, ddof=1) + 1e-30), 1)
            level_z = over_inputs(gap)
            level = layer_level(k_l, model, meas, l)
            m = Model(model.physics.replace(s=level), model.params, model.offsets)
        M = one_step_shots(k_l, m, meas, l)
        C = cell_statistic(M, jnp.asarray(Y, jnp.float32), paired=True, scales=ref.scales[li])
        if len(ref.channels) > 2:
            C = np.concatenate([C, paired_moment_channels(np.asarray(M, np.float64), Y, ref.split)], axis=1)
        Q, p, null_mean, null_sd, _ = q_test(C)
        rows.append({"layer": l, "discrepancy": Q, "se": null_sd, "z": (Q - null_mean) / null_sd if null_sd > 0
                     else float("nan"), "p_value": p, "s": level, "level_z": level_z})
    return rows


def failing_layers(rows, alpha: float = 0.01) -> list[int]:
    """Layers whose one-step check fails at ``alpha`` with Bonferroni over the layers checked."""
    if not rows:
        return []
    return sorted(int(r["layer"]) for r in rows if r["p_value"] < alpha / len(rows))
