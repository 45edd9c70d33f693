"""Compare a model with measurements: the unbiased energy discrepancy, its floor and p-value.

Per cell (one input i x one measured layer l, a vector over the layer's neurons so that
correlations count) the U-statistic energy distance between model shots M and measured
shots Y::

    E_il = 2 mean_{a,b} |M_a - Y_b| - mean_{a!=a'} |M_a - M_a'| - mean_{b!=b'} |Y_b - Y_b'|

has expectation exactly 0 when the model's law equals the device's (the V-statistic of
``scipy.stats.energy_distance`` keeps the diagonal and is biased, so a correct model can
beat its own floor with it). The same U-statistic of each neuron's 1-D marginal is added
(it sees the shape of the noise law, which the vector version in many dimensions barely
does). Each is normalised by the pooled within-data spread of its layer (neuron),
``S_l = mean_i mean_{b!=b'} |Y_b - Y_b'|``, giving two channels per cell,
``E_il / S_l`` and ``mean_j E1_ilj / S1_lj``. Each channel is weighted by one over its
standard deviation across inputs between random halves of the measured shots -- all
constants of the data, so every model is scored on the same scale, and a layer whose
statistic is noisy does not drown one where the model visibly fails. The discrepancy is
``D = mean_i T_i`` with ``T_i`` the weighted mean of the channels of input i (so D is in
units of the per-input noise of the statistic). The floor is the same statistic between random halves of the
measured shots. Inputs are independent, so under the model ``T_i`` are independent with
mean 0 and the p-value is the one-sided Student-t tail of ``D / se(D)`` (the statistic's
distribution under the fitted model, estimated from the inputs themselves; measured
calibration in :mod:`gift_theory.lab.calibrate`).
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
from .._model import forward, sample_noise
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

    discrepancy : D = mean_i T_i (0 in expectation for a correct model)
    se : standard error of D over inputs
    noise_floor : the same statistic between random halves of the measured shots
    floor_se : its standard error
    p_value : one-sided P(D' >= D) under the model (Student t over inputs)
    per_input : (n,) T_i
    per_layer : (L',) mean_i E_il / S_l per measured layer
    layer_ids : the 1-based layer of each entry of per_layer
    cells : (n, L') E_il / S_l
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

    def as_dict(self) -> dict:
        return {"discrepancy": self.discrepancy, "se": self.se, "noise_floor": self.noise_floor,
                "floor_se": self.floor_se, "p_value": self.p_value,
                "per_layer": {f"layer{l}": float(v) for l, v in zip(self.layer_ids, self.per_layer)}}


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


def _halves(key, Y):
    """Random halves (per cell) of the measured shots: two (n, r//2, d) arrays."""
    n, r, _ = Y.shape
    perm = jax.vmap(lambda k: jax.random.permutation(k, r))(jax.random.split(key, n))
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
    params = model.params if model.params is not None else meas.params
    params = tuple(Layer(jnp.asarray(W, jnp.float32), jnp.asarray(b, jnp.float32)) for W, b in params)
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


@dataclasses.dataclass(frozen=True)
class Reference:
    """What a measurement contributes to every comparison, computed once.

    scales : per measured layer, the pooled within-data spreads (S_l, S1_l (d_l,))
    weights : (L', 2) one over the standard deviation across inputs of each channel's
        statistic between random halves of the measured shots (data only, so every model
        is weighed the same way; a layer whose statistic is noisy counts less)
    noise_floor, floor_se : the discrepancy between random halves and its standard error
    floor_per_input : (n,)
    """

    scales: tuple
    weights: np.ndarray
    noise_floor: float
    floor_se: float
    floor_per_input: np.ndarray


def _combine(C, weights):
    """(n, L', 2) channels -> per input T (n,) and per cell (n, L'): weighted means."""
    Cw = C * weights[None]
    return Cw.mean(axis=(1, 2)), Cw.mean(axis=2)


def reference(key, meas: Measurement, splits: int = 2) -> Reference:
    """Scales, channel weights and noise floor of ``meas``: the discrepancy statistic between
    random halves of the measured shots, averaged over ``splits`` random splits."""
    if meas.r < 4:
        raise GiftInputError(f"measurement has {meas.r} shots per input; the noise floor (random halves) needs at least 4")
    if meas.n < 2:
        raise GiftInputError("measurement has 1 input; the p-value (over inputs) needs at least 2")
    layers = meas.layers()
    scales = tuple(layer_scales(Y) for Y in layers)
    F = np.zeros((meas.n, len(layers), 2))
    for s_ in range(splits):
        for li, Y in enumerate(layers):
            A, B = _halves(jax.random.fold_in(key, s_ * 101 + li), jnp.asarray(Y, jnp.float32))
            F[:, li] += cell_statistic(A, B, scales=scales[li])
    F /= splits
    sd = F.std(axis=0, ddof=1) if meas.n > 1 else np.ones(F.shape[1:])
    weights = 1.0 / np.maximum(sd, 1e-12 * max(float(sd.max()), 1e-300))
    Fi, _ = _combine(F, weights)
    m = float(Fi.mean())
    se = float(Fi.std(ddof=1) / np.sqrt(len(Fi))) if len(Fi) > 1 else float("nan")
    return Reference(scales, weights, m, se, Fi)


def noise_floor(key, meas: Measurement, splits: int = 2):
    """``(floor, floor_se)``: see :func:`reference`."""
    ref = reference(key, meas, splits)
    return ref.noise_floor, ref.floor_se


def compare(key, model: Model, meas: Measurement, *, shots: int | None = None, ref: Reference | None = None,
            floor_splits: int = 2) -> Comparison:
    """Score ``model`` against ``meas`` (see the module docstring for the statistic).

    Parameters
    ----------
    key : PRNG key (split into ``model`` and ``floor`` subkeys)
    model : Model
    meas : Measurement (use held-out inputs for a fitted model)
    shots : model shots per input (default: 4 r)
    ref : the measurement's :class:`Reference` if already computed (same for every model)

    Returns
    -------
    Comparison
    """
    k_model, k_floor = jax.random.split(key)
    if ref is None:
        ref = reference(k_floor, meas, floor_splits)
    Ms = model_shots(k_model, model, meas, shots)
    C = np.stack([cell_statistic(M, jnp.asarray(Y, jnp.float32), scales=sc)
                  for M, Y, sc in zip(Ms, meas.layers(), ref.scales)], axis=1)
    T, cells = _combine(C, ref.weights)
    D, se, p = _student_p(T)
    return Comparison(discrepancy=D, se=se, noise_floor=ref.noise_floor, floor_se=ref.floor_se, p_value=p,
                      per_input=T, per_layer=cells.mean(axis=0), layer_ids=meas.layer_ids(), cells=cells)


def one_step_shots(key, model: Model, meas: Measurement, layer: int):
    """The model's layer ``layer`` fed with the *measured* output of the layer before, same
    shot (needs taps for layer >= 2; layer 1 is fed x). Returns (n, r, d_l)."""
    arch = meas.arch
    L = arch.depth
    params = model.params if model.params is not None else meas.params
    W, b = (jnp.asarray(p, jnp.float32) for p in params[layer - 1])
    phys = model.physics
    n, r = meas.n, meas.r
    noise = sample_noise(key, arch, phys, (n, r), jnp.float32)
    t = None if meas.t is None else jnp.asarray(meas.t, jnp.float32)
    s = phys.s
    if layer == 1:
        a = jnp.asarray(meas.x, jnp.float32)[:, None, :]
        if "a0" in noise:
            a = a + s * noise["a0"]
    else:
        a = jnp.asarray(meas.taps[layer - 2], jnp.float32)
    # the core's forward pass for one layer, through the physics' own hooks
    W = phys.effective_weights(W, layer)
    u = a @ W.T
    g = phys.gain(noise, layer, t, u.shape)
    z = (u if g is None else g * u) + b
    if f"w{layer}" in noise:
        z = z + s * noise[f"w{layer}"]
    if layer < L:
        z = arch.sigma(z)
        if f"a{layer}" in noise:
            z = z + s * noise[f"a{layer}"]
    return phys.readout(z, noise, layer)


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
        T = (C * ref.weights[li][None]).mean(axis=1)
        D, se, p = _student_p(T)
        rows.append({"layer": l, "discrepancy": D, "se": se, "z": D / se if se > 0 else float("nan"), "p_value": p})
    return rows
