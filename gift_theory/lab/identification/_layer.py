"""One layer's identification: :func:`identify_layer` composes the named steps of the map, the
time and the noise, each of which returns its rows."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from .. import _memory, _time
from .._qtest import over_inputs
from ._layers import BINS, WIDE, _Layer, _curve, _level, _mean_model, _subset, _unit_cov, _unit_var
from ._map import _fit_map, _map_uncertainty
from ._map_rows import (MapChoice, MapEvidence, _block, dead_neurons, map_covariance, map_rows, restricted_maps,
                        shape_row)
from ._noise import _noise_rows
from ._stats import FULL_COV_MAX, _Blocks, _cell_cov, _cell_var, _gram, _gram_inv, _row, _within, _z_of_p
from ._trend import TREND_SHARE, _within_trend

#: a layer's map is resolved (fitted, its restrictions tested) only with at least this many
#: more inputs than parameters per neuron; else only the programmed map is tested (a
#: 784-input layer at 500 inputs: W_eff cannot be read off, and its normal equations alone
#: were 2.5 GB)
RESOLVE_MARGIN = 10


# ---- per-layer identification ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class LayerIdentity:
    """One layer, identified from the shots.

    layer : 1-based
    W_eff, b_eff : (d, p), (d,) the effective mean map
    theta_se : (d, p+1) standard errors of its entries; infinite for an entry the data do not see
        (an input that is 0 everywhere, a neuron saturated at most inputs, collinear inputs): the
        part of the map they cannot tell from the programmed one is read as the programmed one
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


def _time_columns(t):
    """(t in float64 or None, the inputs' mean times (n, 1) where the map's trends are fitted or
    None). The map is identified at t = 0, the start of the acquisition (reference §2's drift is
    g = 1 + r t): a trend's time average is not a fixed error. Its trends come from the inputs'
    mean times (a within-input trend would make the model's mean move inside an input by a
    coefficient read off the means), fitted only where those spread over a tenth of the campaign
    (not with an interleaved order, where the within-input test sees the trend)."""
    if t is None:
        return None, None
    t = np.asarray(t, np.float64)
    tbar = t.mean(1, keepdims=True)
    return t, (tbar if np.std(tbar) >= 0.1 else None)


#: a hidden neuron's shape is read where z's root-mean-square standard error over the shots is
#: below this, on the activation's own scale (tanh, sigmoid, sin bend over a unit of z)
RESOLVED_Z = 1.0


def _z_error(lay: _Layer, S, full: bool, k: int) -> np.ndarray:
    """Per neuron the root-mean-square standard error of the shots' z from the map's error
    (``S``, its covariance): sqrt(tr(S_i M)), M the shots' second moments of (a, 1)."""
    d, p = lay.W.shape
    Ar = lay.A.reshape(-1, p)  # (no copy of the shots' inputs: a wide layer's are as large as its taps)
    M = np.empty((p + 1, p + 1))
    M[:p, :p] = Ar.T @ Ar / Ar.shape[0]
    M[:p, p] = M[p, :p] = Ar.mean(0)
    M[p, p] = 1.0
    Sd = np.stack([_block(S, full, i, k, p + 1) for i in range(d)])
    v = np.einsum("ikl,kl->i", Sd, M)
    return np.where(np.isfinite(v), np.sqrt(np.maximum(v, 0.0)), np.inf)


def _resolved(lay: _Layer, act: str, S, full: bool, k: int, alive: list, unseen: dict) -> list:
    """The neurons the activation's shape is read on. Under a curved activation, those whose z the
    data resolve: seen in full (along a direction they do not see, W_eff is the fit's noise, and
    so is each shot's z there) and with z's standard error (:func:`_z_error`) below the
    activation's own scale :data:`RESOLVED_Z`. A shot binned at an unresolved z leaves a shared
    "shape" in the residuals that the test's first-order law does not hold (at s = 1 with taps
    the per-input means barely identify a hidden layer's map: z's standard error reached
    1e3-1e5, its z 1e4 on a tanh, and the test rejected 10 % of null files at 0.01). A linear
    layer's residual is linear in the map's error: its law holds as it is, every alive neuron."""
    if not lay.hidden or act == "identity":
        return alive
    z_error = _z_error(lay, S, full, k)
    return [i for i in alive if i not in unseen and z_error[i] < RESOLVED_Z]


def _fit_at_level(lay: _Layer, act: str, s2: float, tt, f2: float, W0=None, b0=None):
    """The map and the noise level in two passes (the smoothing of sigma depends on the level only
    at second order), then the map at the level found: ((W_eff, b_eff, drift, z, m, g, var, X, E),
    s^2, W_eff, b_eff) -- the last two the start of a later fit."""
    for _ in range(2):
        W_eff, b_eff, drift, z, m, g, var, X, E = _fit_map(lay, act, s2, tt, W0=W0, b0=b0)
        W0, b0 = W_eff, b_eff
        obs = _cell_var(_within(E, g, lay.A), lay.res_var) * f2
        vu = _unit_var(lay, W_eff)
        s2 = _level(lambda v: float(np.sum(_mean_model(lay, act, W_eff, b_eff, v, vu, tt, drift)[3].mean(1))),
                    float(np.sum(obs)), s2)
    return _fit_map(lay, act, s2, tt, W0=W0, b0=b0), s2, W0, b0


def _noise_model(lay: _Layer, act: str, fit, mc, E, obs, Chat, f2: float, s2: float, tt, sub):
    """The residuals, variances and covariance the noise is read from, at the map chosen, not at
    the unrestricted W_eff: W_eff's error is one draw shared by every input, so W_eff C W_eff^T (no
    taps: C the hidden layers' propagated noise) carried a bias the test over inputs could not
    average out (correlated_noise on 12 % of null files without taps). A hidden layer's noise is
    bent by its activation at z: at the programmed map when the data keep it, for the same reason
    -- W_eff's error spreads z, |W_eff|^2 ~ |W|^2 + its variance, and the activation's variance at
    the spread z is smaller (at s = 1, W_eff's standard error 0.6 of W on 120 inputs, layer 2's
    level read 1.26 and its kurtosis named noise_law on null files). Returns (E, obs, Chat_s, z, g,
    var, s^2, W_n)."""
    W_eff, b_eff, drift, z, _, g, var = fit[:7]
    choice, gain = mc.choice, mc.gain
    Chat_s = Chat[:, sub][:, :, sub] if Chat is not None else _cell_cov(E[:, :, sub]) * f2
    W_n = (lay.W if choice in ("programmed", "bias", "detector") else gain * lay.W if choice in ("gain", "gain+bias")
           else W_eff)
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
    return E, obs, Chat_s, z, g, var, s2, W_n


def _seen_part(lay: _Layer, theta, unseen: dict, p: int, tt):
    """``(theta, W_eff, b_eff, drift)`` with each neuron's steps along the directions the data do
    not see (``unseen``: {neuron: (mask, projector on the seen directions)}) taken out: what the
    data cannot tell from the programmed map is the programmed map (the fit's steps there were
    free)."""
    for i, (_, proj) in unseen.items():
        theta[i] = proj @ theta[i]
    return (theta, lay.W + theta[:, :p], lay.b + theta[:, p],
            None if tt is None else (theta[:, p + 1], theta[:, p + 2]))


def identify_layer(lay: _Layer, act: str, s_guess: float, t, depth: int, taps: bool,
                   trends: bool = True, memory: bool = True) -> LayerIdentity:
    """One layer's identification: the map at its noise level, the time's terms put into it, the
    map's rows (:mod:`._map_rows`), then the noise's (:mod:`._noise`).

    ``trends``: whether a trend within the inputs' shots may be put into the map (see
    :func:`._trend._within_trend`); ``memory``: whether the layer's memory is tested
    (:mod:`.._memory`; False once it was taken out of the shots)."""
    n, r, d = lay.Y.shape
    p = lay.W.shape[1]
    l = lay.layer
    t, tt = _time_columns(t)
    k = p + 1 + (2 if tt is not None else 0)
    if n < k + RESOLVE_MARGIN:
        return _unresolved_layer(lay, act, s_guess, t, k)
    unc = _map_uncertainty(lay, act, s_guess)
    if unc > 1.0:
        return _unresolved_layer(lay, act, s_guess, t, k, f"its standard error is {unc:.3g} times the map itself: "
                                 f"the mean response barely depends on W at this noise level")
    # the within-cell regression (taps, a regressor varying within an input) spends p degrees
    # of freedom per neuron
    f2 = n * (r - 1) / max(n * (r - 1) - p, 1) if lay.A.shape[1] > 1 else 1.0
    fit, s2, W0, b0 = _fit_at_level(lay, act, s_guess ** 2, tt, f2)
    extra_rows = []
    # a gain wandering over the campaign, a map drifting (.._time), tested beyond the straight lines
    # read below; a named one is put into the map as a known term of the pre-activation
    E_slow, slow = None, None
    if t is not None:
        slow = _time.slow_terms(lay, fit[8], fit[5], fit[7], t, l, _row, _within, fit[6])
        extra_rows.extend(slow.rows)
        if slow.offset is not None:
            E_slow = _within(fit[8], fit[5], lay.A)
            lay = dataclasses.replace(lay, offset=slow.offset)
            fit, s2, W0, b0 = _fit_at_level(lay, act, s2, tt, f2, W0, b0)
    # memory (.._memory), read on the residuals beyond those slow terms; a memory that is named is
    # taken out of the shots and the layer read again, so its mean shift is not read as the map's
    if memory and t is not None:
        lag = _memory.lag_test(l, _within(fit[8], fit[5], lay.A), lay.Y, t, _row, fit[5], lay.A)
        if lag.p < _memory.UNDO_P:
            undone = dataclasses.replace(lay, Y=_memory.undo(lay.Y, lag), offset=None,
                                         memory=(_memory.previous_means(lay.Y, lag), lag.alpha_se))
            inner = identify_layer(undone, act, s_guess, t, depth, taps, trends, memory=False)
            return dataclasses.replace(inner, rows=inner.rows + (lag.row,))
        extra_rows.append(lag.row)
    elif memory:
        extra_rows.append(_memory.lag_test(l, fit[8], lay.Y, None, _row).row)
    E_time = E_slow  # the time tests of the noise read the residuals without the terms put in
    # (the residuals with W_eff's error along each shot's own input removed, as the time tests read them)
    Ew = _within(fit[8], fit[5], lay.A) if tt is None and t is not None else None
    within = _within_trend(lay, Ew, fit[5], t, _cell_var(Ew, lay.res_var)) if Ew is not None and trends else None
    if within is not None:
        # a trend within the inputs' shots: the map is read at t = 0 with it in place (with an
        # interleaved acquisition its time average is the same shift -- or gain -- of every
        # input's z: a bias drift was read as a shifted transfer and named activation_mismatch),
        # and the noise level without it; the time tests read the residuals with it
        E_time = Ew if E_time is None else E_time
        lay = dataclasses.replace(lay, offset=within[0] if lay.offset is None else lay.offset + within[0])
        fit, s2, W0, b0 = _fit_at_level(lay, act, s2, tt, f2, W0, b0)
        Ew = None
    W_eff, b_eff, drift, z, _, g, _, X, _ = fit
    E = _within(fit[8], g, lay.A) if Ew is None else Ew  # (already made for the trend's test)
    obs = _cell_var(E, lay.res_var) * f2
    # the across-neuron covariance per input where the map's covariance or the shape test needs
    # it (d^2 floats per input: not for a wide layer, whose noise tests read a subset)
    Chat = _cell_cov(E) * f2 if (d <= WIDE or d * k <= FULL_COV_MAX) else None

    # ---- the mean map and its restrictions
    G = _gram(X)
    inv = _gram_inv(G)  # one inverse for the covariance, the memory's error and the shape test
    S, full, nu, unseen = map_covariance(lay, X, Chat, obs, r / lay.mean_factor, k, G, inv,
                                         within[1:] if within is not None else None, slow, s2)
    dW, db = W_eff - lay.W, b_eff - lay.b
    theta = np.concatenate([dW, db[:, None]] + ([drift[0][:, None], drift[1][:, None]] if tt is not None else []),
                           axis=1)  # (d, k)
    if unseen:
        theta, W_eff, b_eff, drift = _seen_part(lay, theta, unseen, p, tt)
        dW, db = theta[:, :p], theta[:, p]
    se = (np.sqrt(np.maximum(np.diag(S), 1e-300)).reshape(d, k) if full
          else np.sqrt(np.maximum(np.einsum("ipp->ip", S), 1e-300)))
    transfer_cls = "activation_mismatch" if lay.hidden else "readout_nonlinearity"
    dead, rows = dead_neurons(lay, W_eff, S, full, k, nu, transfer_cls)
    alive = [i for i in range(d) if i not in dead]
    idx = np.concatenate([np.arange(i * k, (i + 1) * k) for i in alive]) if alive else np.zeros(0, int)
    Sa = S[np.ix_(idx, idx)] if full else _Blocks(S[alive])
    seen = _resolved(lay, act, S, full, k, alive, unseen)
    ps, zc, gam, row = shape_row(lay, E, z, X, inv[0], Chat, obs, seen, k, nu, transfer_cls,
                                 left_out=len(alive) - len(seen))
    rows.append(row)
    mc = MapChoice("general", {}, {}, 0.0, 0.0, 1.0, float("inf"), 1.0, float("inf"), 0.0)
    if alive:
        unseen_dims = sum(k - int(round(np.trace(proj))) for i, (_, proj) in unseen.items() if i in alive)
        ev = MapEvidence(lay, act, s2, tt, X, Chat, obs, r / lay.mean_factor, alive, k, theta[alive].ravel(), Sa, nu,
                         transfer_cls, unseen_dims)
        mc = map_rows(ev, restricted_maps(lay.W[alive], lay.b[alive], k, tt is not None), dW, se, theta, E.mean(1),
                      rows, ps)
    curve = _curve(lay, act, s2)

    # ---- the noise
    sub = _subset(d)
    E, obs, Chat_s, z, g, var, s2, W_n = _noise_model(lay, act, fit, mc, E, obs, Chat, f2, s2, tt, sub)
    noise_rows, s_lvl, s_se, kurt = _noise_rows(lay, act, l, t, E, obs, Chat_s, sub, z, g, var, b_eff, s2,
                                                _unit_var(lay, W_n), _unit_cov(lay, W_n, sub), E_time)
    rows.extend(noise_rows)
    _time.attach_share(extra_rows, noise_rows)  # the wander's share of the gain's variance
    if within is not None and within[1] == "gain":
        share = next((r_.get("share") for r_ in noise_rows if r_["test"] == "time_within"), None)
        if share is not None and share < TREND_SHARE:
            # the gain's trend carries little of its variance within the inputs' shots: the path of
            # a fluctuating gain (an AR(1) laser), whose straight line's value at t = 0 means
            # nothing -- the map is read without it (put in, it read a gain of 0.89 at t = 0)
            inner = identify_layer(dataclasses.replace(lay, offset=None), act, s_guess, t, depth, taps, trends=False,
                                   memory=False)
            return dataclasses.replace(inner, rows=inner.rows + tuple(extra_rows))
    se_seen = se.copy()
    for i, (mask, _) in unseen.items():
        se_seen[i, mask] = np.inf  # an entry the data do not see has no finite error
    return LayerIdentity(l, W_eff, b_eff, se_seen, mc.gain, mc.gain_se, tuple(dead), mc.choice, zc, gam, curve,
                         s_lvl, s_se, kurt, tuple(rows) + tuple(extra_rows))
