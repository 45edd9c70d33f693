"""Stage 2 of the lab: the channels of a cell, model shots against measured shots.

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

What a measurement contributes to every comparison -- the layers' scales, the split of its
shots, the channels' weights and the noise floor (the same channels between halves of the
measured shots) -- is computed once, its :class:`Reference`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import _random, _xla
from .._errors import GiftInputError
from .._finite import check_finite
from .._measurement import Measurement
from .._model import named_subkey
from ._qtest import q_test
from ._shots import Model, default_model_shots, shot_blocks, to32


def _pair_dist(A, B):
    """(..., K, d), (..., r, d) -> (..., K, r) Euclidean distances."""
    sq = (jnp.sum(A * A, -1)[..., :, None] + jnp.sum(B * B, -1)[..., None, :]
          - 2.0 * jnp.einsum("...kd,...rd->...kr", A, B))
    return jnp.sqrt(jnp.maximum(sq, 0.0))


def _offdiag_mean(D):
    k = D.shape[-1]
    return (jnp.sum(D, (-2, -1)) - jnp.trace(D, axis1=-2, axis2=-1)) / (k * (k - 1))


def _pairsum(Z):
    """(n, N, d) -> (n, d): sum over unordered pairs of |Z_a - Z_b| per neuron, by sorting
    (numpy: XLA's CPU sort is ~20 times slower for these shapes)."""
    N = Z.shape[1]
    k = np.arange(1, N + 1, dtype=np.float64)
    return np.sort(np.moveaxis(Z, 1, -1), axis=-1) @ (2.0 * k - N - 1.0)


@functools.partial(_xla.jit, static_argnames=("paired",))  # gift's XLA:CPU options: 0.8 of the time
def _vector_energy(M, Y, paired: bool):
    c = jnp.mean(Y, axis=1, keepdims=True)  # centring keeps float32 distances accurate
    M = M - c
    Y = Y - c
    cross = _pair_dist(M, Y)
    cross = _offdiag_mean(cross) if paired else jnp.mean(cross, (-2, -1))
    wm = _offdiag_mean(_pair_dist(M, M))
    wy = _offdiag_mean(_pair_dist(Y, Y))
    return 2.0 * cross - wm - wy, wy


def energy_cells(M, Y, paired: bool = False, chunk: int | None = None):
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

    ``chunk``: the inputs per compiled call, every call padded to it (a block of a larger
    array's inputs passes the whole array's chunk: the compiled program's shape is then the
    whole's, and so are the numbers); default :func:`_input_chunk`.
    """
    n, K, d = np.shape(M)
    r = np.shape(Y)[1]
    # inputs in chunks: the pair distances are (K + r)^2 floats per input (a 50 MB file's 1740
    # inputs x 256 model shots held 0.5 GB of them at once); each chunk the same shape, the last
    # padded, so one compiled program serves them all
    pad_all = chunk is not None
    c = _input_chunk(n, K, r, d) if chunk is None else int(chunk)
    # JAX's arrays read as numpy (no copy on the CPU): a slice of a JAX array is a program of its own
    M, Y = (np.asarray(A) if isinstance(A, jax.Array) else A for A in (M, Y))
    E, wy = np.empty(n), np.empty(n)
    E1, wy1 = np.empty((n, d)), np.empty((n, d))
    for c0 in range(0, n, c):
        sl = slice(c0, min(c0 + c, n))
        m_, y_ = np.asarray(M[sl]), np.asarray(Y[sl])
        k = m_.shape[0]
        if k < c and (n > c or pad_all):  # pad the last chunk to the common shape
            m_ = np.concatenate([m_, np.repeat(m_[-1:], c - k, axis=0)])
            y_ = np.concatenate([y_, np.repeat(y_[-1:], c - k, axis=0)])
        e, w = _vector_energy(m_, y_, paired)  # numpy in: jnp.asarray would compile a copy program per shape
        E[sl], wy[sl] = np.asarray(e, np.float64)[:k], np.asarray(w, np.float64)[:k]
        E1[sl], wy1[sl] = _marginal_energy(m_[:k], y_[:k], paired)
    return E, wy, E1, wy1


#: bytes of pair distances and sorted shots held at once per chunk of inputs
CHUNK_BYTES = 64 << 20


def _input_chunk(n: int, K: int, r: int, d: int) -> int:
    """Inputs per chunk of :func:`energy_cells`: the (K + r)^2 distances (float32, a few temporaries)
    and the (K + r) d sorted values (float64) of each input within :data:`CHUNK_BYTES`."""
    per_input = 12 * (K + r) ** 2 + 24 * (K + r) * d
    return int(max(1, min(n, CHUNK_BYTES // max(per_input, 1))))


def _marginal_energy(M, Y, paired: bool):
    """(E1, wy1) of :func:`energy_cells` for one chunk of inputs (float64 numpy)."""
    Mn, Yn = np.asarray(M, np.float64), np.asarray(Y, np.float64)
    c = Yn.mean(axis=1, keepdims=True)
    Mn, Yn = Mn - c, Yn - c
    K, r = Mn.shape[1], Yn.shape[1]
    pm, py = _pairsum(Mn), _pairsum(Yn)
    c1 = _pairsum(np.concatenate([Mn, Yn], axis=1)) - pm - py  # all cross pairs
    if paired:
        c1 = (c1 - np.sum(np.abs(Mn - Yn), axis=1)) / (K * r - K)
    else:
        c1 = c1 / (K * r)
    wm1 = 2.0 * pm / (K * (K - 1))
    wy1 = 2.0 * py / (r * (r - 1))
    return 2.0 * c1 - wm1 - wy1, wy1


def cell_statistic(M, Y, paired: bool = False, scales=None, chunk: int | None = None):
    """The two normalised channels of a cell, shape (n, 2): the vector energy distance over
    the layer's pooled spread, and the mean over neurons of each neuron's energy distance
    over its pooled spread.

    ``scales`` (from :func:`layer_scales`) fixes the normalisation; default: from ``Y``.
    ``chunk``: see :func:`energy_cells`.
    """
    E, wy, E1, wy1 = energy_cells(M, Y, paired, chunk)
    E, wy, E1, wy1 = (np.asarray(a, np.float64) for a in (E, wy, E1, wy1))
    if scales is None:
        scales = (wy.mean(), wy1.mean(0))
    S, S1 = scales
    return np.stack([E / max(S, 1e-30), np.mean(E1 / np.maximum(S1, 1e-30), axis=1)], axis=1)


def within_spreads(Y):
    """A measured layer's within-data spreads (float64 numpy): ``wy`` (n,) the mean over pairs of
    shots b != b' of |Y_b - Y_b'| (the vector over neurons) and ``wy1`` (n, d) the same of each
    neuron -- the ``wy`` and ``wy1`` of :func:`energy_cells`, without a model."""
    Y = np.asarray(Y, np.float64)
    n, r, d = Y.shape
    Yc = Y - Y.mean(axis=1, keepdims=True)
    wy = np.empty(n)
    chunk = max(1, int(4e6 // max(r * r, 1)))
    for c0 in range(0, n, chunk):
        Z = Yc[c0:c0 + chunk]
        sq = np.sum(Z * Z, -1)
        D = np.sqrt(np.maximum(sq[:, :, None] + sq[:, None, :] - 2.0 * (Z @ np.swapaxes(Z, 1, 2)), 0.0))
        wy[c0:c0 + chunk] = (D.sum((1, 2)) - np.trace(D, axis1=1, axis2=2)) / (r * (r - 1))
    return wy, 2.0 * _pairsum(Yc) / (r * (r - 1))


def layer_scales(Y):
    """The pooled within-data spreads of a measured layer Y (n, r, d): ``(S, S1 (d,))``."""
    wy, wy1 = within_spreads(Y)
    return float(np.mean(wy)), wy1.mean(0)


def _halves(key, Y):
    """Random halves (per cell) of the measured shots Y (n, r, d), float32: two (n, r//2, d)
    arrays (each input's shots in the order of ``jax.random.permutation`` of its key of
    ``jax.random.split(key, n)``, by :func:`gift_theory._random.split_permutations`; the gather
    on the host, exact)."""
    n, r, _ = Y.shape
    perm = _random.split_permutations(key, n, r)
    Yp = np.take_along_axis(np.asarray(Y, np.float32), perm[:, :, None], axis=1)
    h = r // 2
    return to32(Yp[:, :h]), to32(Yp[:, h:2 * h])




# ---- the moment channels ------------------------------------------------------------------

#: every channel of a cell, in order (the moment channels need r >= 8 shots)
CHANNELS = ("energy", "energy_marginal", "variance", "correlation", "shape")
#: fewest shots per input for the moment channels (their noise floor splits shots in quarters)
MIN_SHOTS_MOMENTS = 8


def _variance_floor(Y):
    """A variance floor of a measured layer Y (n, r, d) for the features (a data constant)."""
    return 1e-3 * float(np.mean(np.var(Y, axis=1)) + 1e-30)


def _top_eigenvalue(c, iters: int = 24):
    """The top eigenvalue of each cell's scatter c^T c (c: (n, h, d) centred shots), by power
    iteration from a fixed start on the smaller of the two Gram forms. A deterministic function
    of the cell's shots, which is all a split-half product needs (the same f on data and model);
    it converges to the top eigenvalue, and meanwhile lies between the top two. The start is not
    the all-ones vector: with no more shots than neurons the Gram form is c c^T, whose null space
    holds the ones (the shots are centred), so a ones start iterated on rounding noise -- 0 for
    shots with float32 mantissas, the top eigenvalue for float64 ones: a float64 file failed its
    correlation channel at z = 10 against float32 model shots of the same law."""
    ct = np.swapaxes(c, 1, 2)
    A = c @ ct if c.shape[1] <= c.shape[2] else ct @ c
    k = A.shape[1]
    x = np.broadcast_to(np.linspace(1.0, 2.0, k)[:, None], A.shape[:2] + (1,)).copy()
    for _ in range(iters):
        x = A @ x
        x /= np.sqrt(np.sum(x * x, axis=1, keepdims=True)) + 1e-300
    return np.sum(x * (A @ x), axis=(1, 2))


def _features(S, eps):
    """Cell features of samples S (n, h, d): per-neuron log variance (n, d), log top
    eigenvalue of the shot covariance (n, 1), pooled standardised fourth moment (n, 1).
    ``eps`` (a variance floor of the layer, a data constant) keeps quantised cells finite."""
    c = S - S.mean(axis=1, keepdims=True)
    h = S.shape[1]
    c2 = c * c
    v = np.sum(c2, axis=1) / (h - 1)
    lmax = _top_eigenvalue(c) / (h - 1) if S.shape[2] > 1 else v[:, 0]
    z2 = c2 / (v + eps)[:, None, :]
    return (np.log(v + eps), np.log(np.maximum(lmax, 0.0) + eps)[:, None], np.mean(z2 * z2, axis=(1, 2))[:, None])


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
    """``Y[i, idx[i, k], :]`` (n, k, d): shots of each input by index, one gather of rows."""
    n, r, d = Y.shape
    rows = idx + (np.arange(n) * r)[:, None]
    return np.asarray(Y).reshape(n * r, d)[rows]


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
    Y = np.asarray(Y, np.float64)
    K = M.shape[1]
    _check_moment_shots(K, Y.shape[1])
    return _moment_rows(M, Y, split, _model_sets(rng, Y.shape[0], K), _variance_floor(Y))


def _check_moment_shots(K: int, r: int) -> None:
    if K < 2 * (r // 2):
        raise GiftInputError(f"compare: {K} model shots per input; the moment channels need at least {2 * (r // 2)}")


def _model_sets(rng, n: int, K: int):
    """(n, K): each input's model shots in a random order (sets of h in a row), from ``rng``."""
    return rng.permuted(np.tile(np.arange(K), (n, 1)), axis=1)


def _moment_rows(M, Y, split, perm, eps):
    """:func:`moment_channels` of the inputs of ``M`` and ``Y`` (float64), their model sets
    ``perm`` and the layer's variance floor ``eps``: a function of each input's rows alone."""
    n, r, d = Y.shape
    h = r // 2
    K = M.shape[1]
    reps = K // (2 * h)
    out = np.empty((n, 3))
    c = _input_chunk(n, K, r, d)  # the model's shots in float64, a chunk of inputs at a time
    for c0 in range(0, n, c):
        sl = slice(c0, min(c0 + c, n))
        Mp = _take(np.asarray(M[sl], np.float64), perm[sl, :2 * reps * h])  # permuted: sets of h in a row
        MA = [Mp[:, 2 * q * h:(2 * q + 1) * h] for q in range(reps)]
        MB = [Mp[:, (2 * q + 1) * h:(2 * q + 2) * h] for q in range(reps)]
        out[sl] = _product_channels(_take(Y[sl], split[sl, :h]), _take(Y[sl], split[sl, h:2 * h]), MA, MB, eps)
    return out


def paired_moment_channels(M, Y, split, eps: float | None = None):
    """The moment channels of a one-step check, (n, 3): model shot k was fed the measured input
    of shot k, so the model's halves are the data's (``split``): each half's difference then
    depends on that half's shots only, and the product of the two has mean zero under the model.
    ``eps``: the layer's variance floor (default from ``Y``; a block of a layer's inputs passes
    the whole layer's, :func:`_variance_floor`)."""
    M = np.asarray(M, np.float64)
    Y = np.asarray(Y, np.float64)
    h = Y.shape[1] // 2
    eps = _variance_floor(Y) if eps is None else eps
    A, B = split[:, :h], split[:, h:2 * h]
    return _product_channels(_take(Y, A), _take(Y, B), [_take(M, A)], [_take(M, B)], eps)


def floor_moment_channels(Y, split):
    """The moment channels between the halves of the measured shots (quarters of r/4 shots)."""
    Y = np.asarray(Y, np.float64)
    q = Y.shape[1] // 4
    eps = _variance_floor(Y)
    A1, A2, B1, B2 = (_take(Y, split[:, i * q:(i + 1) * q]) for i in range(4))
    return _product_channels(B1, B2, [A1], [A2], eps)


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


def combine(C, weights):
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
    split = _random.split_permutations(k_split, meas.n, meas.r)
    moments = meas.r >= MIN_SHOTS_MOMENTS
    channels = CHANNELS if moments else CHANNELS[:2]
    F = np.zeros((meas.n, len(layers), len(channels)))
    for li, Y in enumerate(layers):
        Y32 = np.asarray(Y, np.float32)  # once per layer, not per split
        for s_ in range(splits):
            A, B = _halves(jax.random.fold_in(jax.random.fold_in(k_floor, li), s_), Y32)
            F[:, li, :2] += cell_statistic(A, B, scales=scales[li]) / splits
        if moments:
            F[:, li, 2:] = floor_moment_channels(Y, split)
        check_finite(F[:, li], lambda: f"the noise floor's channels of layer {meas.layer_ids()[li]} (the measured "
                                       f"shots' distances and moments in float32; values up to "
                                       f"{float(np.max(np.abs(Y))):.3g})")
    sd = F.std(axis=0, ddof=1)
    weights = 1.0 / np.maximum(sd, 1e-12 * max(float(sd.max()), 1e-300))
    Q, _, _, null_sd, _ = q_test(F.reshape(meas.n, -1))
    Fi, _ = combine(F, weights)
    return Reference(scales, split, channels, weights, Q, null_sd, Fi)


def noise_floor(key, meas: Measurement, splits: int = 2):
    """``(floor, floor_se)``: see :func:`reference`."""
    ref = reference(key, meas, splits)
    return ref.noise_floor, ref.floor_se


def channel_values(key, model: Model, meas: Measurement, ref: Reference, shots: int | None = None) -> np.ndarray:
    """The channels of every cell, (n, L', C): input x measured layer x channel of ``ref``.

    Each input's channels are a function of its own shots, so the model's shots are made and
    read a block of inputs at a time (:func:`~._shots.shot_blocks`): the numbers are those of the
    whole array, and a large file's model shots are never held at once."""
    if shots is not None and int(shots) < meas.r:
        raise GiftInputError(f"compare: --shots {shots} model shots per input; at least the measured {meas.r} needed")
    K = default_model_shots(meas.r) if shots is None else int(shots)
    moments = len(ref.channels) > 2
    layers = meas.layers()
    if moments:
        _check_moment_shots(K, meas.r)
        rng = np.random.default_rng(np.asarray(jax.random.key_data(named_subkey(key, "model_sets"))).ravel())
        sets = [_model_sets(rng, meas.n, K) for _ in layers]  # drawn in the order the layers read them
        Y64 = [np.asarray(Y, np.float64) for Y in layers]
        eps = [_variance_floor(Y) for Y in Y64]
    C = np.zeros((meas.n, len(layers), len(ref.channels)))
    chunks = [_input_chunk(meas.n, K, meas.r, Y.shape[2]) for Y in layers]  # the whole array's
    for sl, Ms in shot_blocks(named_subkey(key, "shots"), model, meas, shots):
        for li, (M, Y, sc) in enumerate(zip(Ms, layers, ref.scales)):
            C[sl, li, :2] = cell_statistic(M, to32(Y[sl]), scales=sc, chunk=chunks[li])
            if moments:
                C[sl, li, 2:] = _moment_rows(M, Y64[li][sl], ref.split[sl], sets[li][sl], eps[li])
    return C
