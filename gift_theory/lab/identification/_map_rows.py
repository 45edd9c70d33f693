"""The map's rows of one layer: its covariance, the dead neurons, the shape of z shared by the
neurons, the smallest restricted map the data do not reject and the rows that name it (gain,
transfer, per-neuron gains, a detector, bias shifts, a general weight error, a trend of the map)."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from .._level import ALPHA
from ._layers import MC_ATTENUATION, _Layer
from ._map import _bin_shares, _detector_or_modulator, _score_given_shape, _score_omnibus, _shape_given_detector
from ._stats import (FULL_COV_MAX, _Blocks, _chi2, _covariance, _gls_all, _gram_inv, _row, _solve_psd, _sub,
                     _two_sided, _wald, _z_of_p)
from ._trend import _robust_trend_p


def map_covariance(lay: _Layer, X, Chat, obs, r_eff: float, k: int, G, inv, trend=None, slow=None, s2=None):
    """The sandwich covariance of the map's entries (:func:`._stats._covariance`) with the error of
    the trends put into it: ``trend`` (kind, se) of a straight line within the inputs' shots (the
    map at t = 0 carries its error times the inputs' mean time: on the biases, additive per neuron,
    or along W as a common gain, rank one) and ``slow`` the wander's or drift's (:mod:`.._time`).
    ``G`` is the design's Gram and ``inv`` its :func:`._stats._gram_inv` (the caller's, which the
    shape test shares). Returns (S, full, nu, unseen): ``nu`` the covariance's own degrees of freedom, r - 1 per input,
    the inputs weighted by their leverage; ``unseen`` the neurons whose map the data see only in
    part (:func:`._stats._gram_inv`; with ``s2``, the level, also the directions where the Monte
    Carlo regressor of a layer without taps is mostly its draws' error)."""
    d, p = lay.W.shape
    N = None
    if s2 is not None and lay.draws and lay.Cin is not None and lay.Cin.ndim == 3 and not lay.hidden:
        # no taps: the regressor is the Monte Carlo mean of the layer before, its error per input
        # s^2 Cin / draws (the output is linear in it: the design's error is the regressor's)
        N = np.zeros((k, k))
        N[:p, :p] = s2 * lay.Cin.sum(0) / lay.draws
    S, full, unseen = _covariance(X, Chat, obs, r_eff, inv if N is None else _gram_inv(G, N, MC_ATTENUATION))
    if trend is not None:
        kind, se = trend
        if kind == "additive":
            if full:
                S[np.arange(d) * k + p, np.arange(d) * k + p] += se ** 2
            else:
                S[np.arange(d), p, p] += se ** 2
        else:
            v = np.zeros((d, k))
            v[:, :p] = lay.W
            if full:
                S += se ** 2 * np.outer(v.ravel(), v.ravel())
            else:
                S += se ** 2 * v[:, :, None] * v[:, None, :]
    if slow is not None and slow.cov is not None:
        from .. import _time

        _time.add_cov(S, full, slow.cov, k)
    if lay.memory is not None:  # alpha's error, through the means it moved (-alpha P), rank one
        P, se_a = lay.memory
        Binv = inv[0]
        v = np.einsum("iab,ib->ia", Binv, np.einsum("nib,ni->ib", X, P))  # (d, k): theta per unit of alpha
        S += se_a ** 2 * (np.outer(v.ravel(), v.ravel()) if full else v[:, :, None] * v[:, None, :])
    r = lay.Y.shape[1]
    lev = np.einsum("nip->n", X ** 2)
    nu = float(lev.sum() ** 2 / max(np.sum(lev ** 2), 1e-300)) * max(r - 1, 1)
    return S, full, nu, unseen


def _block(S, full: bool, i: int, k: int, p: int):
    return S[i * k:i * k + p, i * k:i * k + p] if full else S[i, :p, :p]


def dead_neurons(lay: _Layer, W_eff, S, full: bool, k: int, nu: float, cls: str):
    """The neurons whose effective row is compatible with 0 where the programmed row is rejected
    (Bonferroni over the layer's neurons), and their row (a list of at most one). Both Wald tests
    read the directions of the row the data identify (a neuron saturated at most inputs has
    fewer than its p), with that many degrees of freedom; a row with none is not tested."""
    d, p = lay.W.shape
    dW = W_eff - lay.W
    dead, dead_p, tests = [], [], {}
    for i in range(d):
        Si = _block(S, full, i, k, p)
        (q0, m0), (q1, m1) = _wald(Si, W_eff[i]), _wald(Si, dW[i])
        if m0 == 0 or np.linalg.norm(lay.W[i]) == 0:
            continue
        p0, p1 = _chi2(q0, m0, nu)[0], _chi2(q1, m1, nu)[0]
        tests[i] = (q1, m1)
        if p0 >= ALPHA and p1 * d < ALPHA:
            dead.append(i)
            dead_p.append(min(1.0, p1 * d))
    if not dead:
        return dead, []
    j = int(np.argmin(dead_p))
    q1, m1 = tests[dead[j]]
    l = lay.layer
    seen = "" if m1 == p else f" (on the {m1} of its {p} directions the data identify)"
    return dead, [_row(cls, "dead", min(dead_p), _chi2(q1, m1, nu)[1], len(dead),
                       f"neuron(s) {', '.join(f'{l}:{i}' for i in dead)} respond to nothing: effective row 0 "
                       f"(the programmed row rejected, p = {dead_p[j]:.2g}{seen}); a dead or stuck neuron", dead)]


def restricted_maps(Wa, ba, k: int, timed: bool) -> dict:
    """The designs of the restricted maps on the alive neurons' stacked (W_eff - W, b_eff - b)
    (columns: how theta moves with each parameter); the time trends, when there are times, are
    free in every map."""
    da, p = Wa.shape

    def unit(pos):  # per alive neuron, the column moving entry ``pos`` of its theta
        R = np.zeros((da * k, da))
        R[np.arange(da) * k + pos, np.arange(da)] = 1.0
        return R

    free = np.concatenate([unit(p + 1), unit(p + 2)], axis=1) if timed else np.zeros((da * k, 0))
    pad = np.zeros((da, k - p - 1))
    Rg = np.concatenate([Wa, np.zeros((da, 1)), pad], axis=1).reshape(-1, 1)
    Rb = unit(p)
    Rt = np.stack([np.concatenate([Wa, ba[:, None], pad], axis=1).ravel(), Rb.sum(1)], axis=1)
    Rr = np.zeros((da * k, da))  # per-neuron gain on the whole pre-activation (W and b of that row)
    for a_ in range(da):
        Rr[a_ * k:a_ * k + p + 1, a_] = np.concatenate([Wa[a_], [ba[a_]]])
    return {"programmed": free, "gain": np.concatenate([Rg, free], 1), "transfer": np.concatenate([Rt, free], 1),
            "bias": np.concatenate([Rb, free], 1), "gain+bias": np.concatenate([Rg, Rb, free], 1),
            "rows": np.concatenate([Rr, Rb, free], 1)}


def shape_row(lay: _Layer, E, z, X, Bx, Chat, obs, alive, k: int, nu: float, cls: str, left_out: int = 0):
    """The activation's shape: the binned residual shared by the neurons ``alive`` (none: not
    read, p = 1), beyond each neuron's affine map (``Bx``: per neuron the inverse of the design's
    Gram, :func:`._stats._gram_inv`); ``left_out`` how many neurons the caller left out (whose z
    the data do not resolve), named in the row. Returns (p, bin centres, the shared shape, its row)."""
    r, mf = lay.Y.shape[1], lay.mean_factor
    ebar = E.mean(1)
    zz = z[:, :, alive] if alive else z
    edges, H = _bin_shares(zz, z)  # H: (n, d, B)
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
    if lay.memory is not None:  # alpha's error moved the means along P (see _Layer.memory)
        wg = np.einsum("nib,ni->b", Ht, lay.memory[0][:, alive])
        Vg = Vg + lay.memory[1] ** 2 * np.outer(wg, wg)
    w_, U_ = np.linalg.eigh(Vg)
    keep = w_ > 1e-9 * max(w_.max(), 1e-300)
    qs = float(np.sum((U_[:, keep].T @ Sg) ** 2 / w_[keep]))
    ps, zs_ = _chi2(qs, int(keep.sum()), nu)
    gam = np.linalg.pinv(np.einsum("nib,nic->bc", Ht, Ht)) @ Sg
    inner = edges[1:-1]
    zc = np.concatenate([[inner[0] - 0.5 * (inner[1] - inner[0])], 0.5 * (inner[:-1] + inner[1:]),
                         [inner[-1] + 0.5 * (inner[-1] - inner[-2])]])
    jmax = int(np.argmax(np.abs(gam)))
    note = (f" (read on the {len(alive)} neurons whose z the data resolve; {left_out} left out: their map seen only in "
            "part or their z's error beyond the activation's scale)" if left_out and alive else "")
    row = (_row(cls, "shape", ps, zs_, float(np.max(np.abs(gam))),
                f"the residual at layer {lay.layer} is a function of z shared by its neurons: {gam[jmax]:+.3g} "
                f"near z = {zc[jmax]:.2g} beyond each neuron's affine map" + note) if alive else
           _row(cls, "shape", 1.0, 0.0, 0.0, f"the activation's shape at layer {lay.layer} is not read: no neuron's map "
                "is alive with its z resolved by the data (its map seen in full, z's error within the activation's "
                "scale)"))
    return ps, zc, gam, row


@dataclasses.dataclass(frozen=True)
class MapEvidence:
    """What the rows of one layer's map are read from: the layer, its activation and level, the
    mean-map's design ``X``, the within-input residuals' covariances (``Chat`` or None, ``obs``),
    the effective shots per mean ``r_eff``, the alive neurons, the stacked deviation ``th`` of
    their (W_eff - W, b_eff - b[, trends]) and its covariance ``Sa``, the covariance's degrees of
    freedom ``nu``, the class a transfer is named under, and ``unseen_dims``: how many directions of
    ``th`` the data do not see (:func:`._stats._gram_inv`; ``Sa`` is 0 along them and a misfit
    counts only the rest)."""

    lay: _Layer
    act: str
    s2: float
    tt: np.ndarray | None
    X: np.ndarray
    Chat: np.ndarray | None
    obs: np.ndarray
    r_eff: float
    alive: list
    k: int
    th: np.ndarray
    Sa: object
    nu: float
    cls: str
    unseen_dims: int = 0

    @property
    def da(self) -> int:
        return len(self.alive)

    @property
    def p(self) -> int:
        return self.lay.W.shape[1]


@dataclasses.dataclass(frozen=True)
class MapChoice:
    """The smallest restricted map not rejected and what the rows of the map need of it."""

    choice: str
    fits: dict
    pfit: dict
    p_omni: float
    z_omni: float
    gain: float
    gain_se: float
    g_ols: float
    g_se_tot: float
    rel: float


def choose_map(ev: MapEvidence, models: dict, dW, se) -> MapChoice:
    """The restricted maps fitted by GLS and tested; the programmed map by a score test at it (no
    fitted map: a weakly identified neuron, e.g. a saturated one, can wander far in W_eff, and a
    Wald test there rejected the programmed map on 10 % of null files at layer 2 of 12-24-12-6
    with taps); the first map in order not rejected at :data:`ALPHA` is chosen (where both fit,
    biases near 0, a hidden layer's is read as its activation's slope, the output's as a gain on
    its weighted sum); the common gain read off by projection on W."""
    lay, alive, p = ev.lay, ev.alive, ev.p
    fits = _gls_all(ev.th, ev.Sa, models)
    seen = ev.th.size - ev.unseen_dims
    pfit = {name: _chi2(f[2], seen - models[name].shape[1], ev.nu)[0] for name, f in fits.items()}
    p_omni, z_omni = _score_omnibus(lay, ev.act, ev.s2, ev.tt, ev.Chat, ev.obs, ev.r_eff, alive, ev.nu)
    order = (("programmed", "transfer", "gain") if lay.hidden else ("programmed", "gain", "transfer")) \
        + ("bias", "gain+bias", "rows")
    choice = "general"
    for name in order:
        if (p_omni if name == "programmed" else pfit[name]) >= ALPHA:
            choice = name
            break
    phi, Fi, _ = fits["gain+bias"]
    gain, gain_se = 1.0 + float(phi[0]), float(np.sqrt(max(Fi[0, 0], 0.0)))
    # beyond a gain, the gain is read off by projection on W (unweighted: weights that depend on
    # the data would correlate with a weight error E), its error the noise's plus E's scatter
    # tau^2 per entry (the excess of E beyond the gain over its noise): <E, W> / |W|^2
    Wa = lay.W[alive]
    w2 = float(np.sum(Wa ** 2))
    g_ols = 1.0 + float(np.sum(dW[alive] * Wa)) / max(w2, 1e-300)
    Eg = dW[alive] - (g_ols - 1.0) * Wa
    tau2 = max(0.0, float(np.mean(Eg ** 2) - np.mean(se[alive, :p] ** 2)))
    wv = Wa.ravel()
    W_idx = (np.arange(ev.da)[:, None] * ev.k + np.arange(p)[None, :]).ravel()
    q_w = (float(np.einsum("ip,ipq,iq->", Wa, ev.Sa.blocks[:, :p, :p], Wa)) if isinstance(ev.Sa, _Blocks)
           else float(wv @ ev.Sa[np.ix_(W_idx, W_idx)] @ wv))
    g_se_tot = float(np.sqrt(max(q_w, 0.0) / max(w2, 1e-300) ** 2 + tau2 / max(w2, 1e-300)))
    rel = float(np.sqrt(np.mean(Eg ** 2)) / max(np.sqrt(np.mean(Wa ** 2)), 1e-300))
    if choice in ("gain+bias", "general"):
        gain = g_ols
    return MapChoice(choice, fits, pfit, p_omni, z_omni, gain, gain_se, g_ols, g_se_tot, rel)


def shape_free_p(ev: MapEvidence, rows: list, p_shape: float):
    """When the residual has a shape of z shared by the neurons (the shape test rejects), the map
    tested again given that shape: a transfer that is not the programmed activation moves the
    fitted map too (weight_error led activation_mismatch on an asymmetric modulator, a sin
    modulator and a square-law detector, the right class listed second); the shape's row says
    what it found. None where not tested."""
    if not (p_shape < ALPHA and ev.Chat is not None and ev.da * ev.k <= FULL_COV_MAX):
        return None
    p_free = _score_given_shape(ev.lay, ev.act, ev.s2, ev.tt, ev.Chat, ev.r_eff, ev.alive, ev.nu)
    for rw in rows:
        if rw["test"] == "shape":
            rw["evidence"] += (f"; given that shape the map is the programmed one (p = {p_free:.2g})"
                               if p_free >= ALPHA else f"; the map deviates beyond that shape too (p = {p_free:.2g})")
    return p_free


def _gain_row(ev: MapEvidence, mc: MapChoice, floor) -> dict:
    z_gain = (mc.gain - 1.0) / mc.gain_se if mc.gain_se > 0 else 0.0
    return _row("gain_error", "gain", floor(_two_sided(z_gain)), abs(z_gain), mc.gain - 1.0,
                f"W_eff = {mc.gain:.3f} W at layer {ev.lay.layer} (+- {mc.gain_se:.2g}); nothing else of the map "
                f"differs (p = {mc.pfit['gain']:.2g})")


def _transfer_row(ev: MapEvidence, mc: MapChoice, floor) -> dict:
    phi_t, Fi_t, _ = mc.fits["transfer"]
    qt = float(phi_t[:2] @ np.linalg.solve(Fi_t[:2, :2], phi_t[:2]))
    pt, zt = _chi2(qt, 2, ev.nu)
    return _row(ev.cls, "transfer", floor(pt), zt, phi_t[0],
                f"z scaled as a whole at layer {ev.lay.layer}: {1 + phi_t[0]:.3f} (W, b) + {phi_t[1]:.3g} "
                f"(a {'slope/shift of the activation' if ev.lay.hidden else 'gain/offset of the readout'}; "
                f"fits, p = {mc.pfit['transfer']:.2g})")


def _neuron_transfer_row(ev: MapEvidence, mc: MapChoice, rows: list, floor):
    """Each neuron's own gain and shift of z: a modulator's, or (hidden, fitting better after the
    activation) a detector's. Returns (row, the trend's p on the detector's residual or 0)."""
    lay, da, l = ev.lay, ev.da, ev.lay.layer
    phi_r, Fi_r, _ = mc.fits["rows"]
    qr = float(phi_r[:2 * da] @ _solve_psd(Fi_r[:2 * da, :2 * da], phi_r[:2 * da]))
    pr, zr = _chi2(qr, 2 * da, ev.nu)
    gi = phi_r[:da]
    where, cls_r = ("detector", "readout_nonlinearity") if not lay.hidden else ("modulator", ev.cls)
    text, p_time_det = "", 0.0
    if lay.hidden:
        q_det, q_mod, _, p_sh, p_tdet = _detector_or_modulator(lay, ev.act, ev.s2, ev.obs, lay.mean_factor, ev.alive,
                                                               ev.tt)
        if q_det < q_mod:
            where, cls_r = "detector", "readout_nonlinearity"
            _shape_given_detector(rows, p_sh)
            p_time_det = p_tdet
        text = (f"; as a {where}'s it fits better: weighted squared residual {min(q_det, q_mod):.4g} "
                f"against the {'modulator' if where == 'detector' else 'detector'}'s {max(q_det, q_mod):.4g} "
                f"over {lay.Y.shape[0]} x {da} means")
    row = _row(cls_r, "neuron_transfer", floor(pr), zr, float(np.sqrt(np.mean(gi ** 2))),
               f"each neuron's z at layer {l} scaled and shifted on its own: gains "
               f"{1 + gi.min():.3f}..{1 + gi.max():.3f} on (W, b) of its row, shifts rms "
               f"{np.sqrt(np.mean(phi_r[da:2 * da] ** 2)):.3g} (a {where}'s gain and offset; fits, "
               f"p = {mc.pfit['rows']:.2g}{text})")
    return row, p_time_det


def _detector_row(ev: MapEvidence, rows: list, floor):
    """No restricted map of z fits a hidden layer: the neurons' own gains and offsets may act after
    the activation (a detector, D of reference §2), which no map of z expresses. Returns (row or
    None, the trend's p on the detector's residual or 0)."""
    lay, da, l = ev.lay, ev.da, ev.lay.layer
    q_det, q_mod, q_prog, p_sh, p_tdet = _detector_or_modulator(lay, ev.act, ev.s2, ev.obs, lay.mean_factor, ev.alive,
                                                                ev.tt)
    df_det = lay.Y.shape[0] * da - 2 * da
    if stats.chi2.sf(q_det, df_det) < ALPHA:
        return None, 0.0
    _shape_given_detector(rows, p_sh)
    p_lr = float(stats.chi2.sf(max(q_prog - q_det, 0.0), 2 * da))
    return _row("readout_nonlinearity", "neuron_transfer", floor(p_lr), _z_of_p(max(p_lr, 1e-300)),
                float(np.sqrt(max(q_prog - q_det, 0.0) / max(q_prog, 1e-300))),
                f"each neuron of layer {l} has its own gain and offset after the activation (a "
                f"detector's: g_i sigma(z) + o_i fits the per-input means, chi2 {q_det:.0f} on "
                f"{df_det} df, where no map of z does and a modulator's sigma(g_i z + o_i) leaves "
                f"{q_mod:.0f}; against the programmed map chi2 {q_prog - q_det:.0f} on {2 * da} df)"), p_tdet


def _beyond_gain_rows(ev: MapEvidence, mc: MapChoice, choice: str, models: dict, floor) -> list:
    """The rows of a map with bias shifts (``bias``, ``gain+bias``) or none restricted
    (``general``): the common gain, the weight error beyond it, the bias shifts in the least
    restrictive map not rejected (general: W free)."""
    lay, da, k, p, l, alive, th = ev.lay, ev.da, ev.k, ev.p, ev.lay.layer, ev.alive, ev.th
    rows = []
    if choice in ("gain+bias", "general"):
        z_gain = (mc.gain - 1.0) / mc.g_se_tot if mc.g_se_tot > 0 else 0.0
        rows.append(_row("gain_error", "gain", floor(_two_sided(z_gain)), abs(z_gain), mc.gain - 1.0,
                         f"common gain {mc.gain:.3f} on W at layer {l} (+- {mc.g_se_tot:.2g} with the rest of "
                         f"the map's error)"))
    if choice == "general":
        q_w = mc.fits["gain+bias"][2]
        df_w = th.size - ev.unseen_dims - models["gain+bias"].shape[1]
        pw, zw = _chi2(q_w, df_w, ev.nu)
        rows.append(_row("weight_error", "map", floor(pw), zw, mc.rel,
                         f"W_eff - W beyond a gain and bias shifts at layer {l}: rms {mc.rel:.2g} of rms W "
                         f"(chi2 {q_w:.0f} on {df_w} df)"))
    b_idx = np.arange(da) * k + p
    if choice == "general":
        dbs, Sb = th[b_idx], _sub(ev.Sa, b_idx)
    else:
        phi_b, Fi_b, _ = mc.fits[choice]
        o = 1 if choice == "gain+bias" else 0
        dbs, Sb = phi_b[o:o + da], Fi_b[o:o + da, o:o + da]
    qb = float(dbs @ _solve_psd(Sb, dbs))
    pb, zb = _chi2(qb, da, ev.nu)
    zs = dbs / np.sqrt(np.maximum(np.diag(Sb), 1e-300))
    worst = int(np.argmax(np.abs(zs)))
    rows.append(_row("bias_offset", "bias", floor(pb), zb, float(np.sqrt(np.mean(dbs ** 2))),
                     f"per-neuron shifts of z at layer {l}: rms {np.sqrt(np.mean(dbs ** 2)):.3g}, "
                     f"largest {dbs[worst]:+.3g} at {l}:{alive[worst]} (z = {zs[worst]:.1f})", [alive[worst]]))
    return rows


def time_map_row(ev: MapEvidence, theta, ebar, p_time_det: float) -> dict:
    """The map's trend over acquisition time (the inputs' mean times), against the noise and
    against the inputs' own scatter: a misfit of the mean that is no trend (a saturating
    readout's curve beyond the shape's bins) enters the trend's estimate at random, and the
    noise's covariance alone does not count it (layer 1 of a saturating 6-12-6-4 chip: a "trend"
    at p = 1e-65, none within the shots); a detector's layer reads it on the detector's residual."""
    da, k, p, l, alive, th, Sa = ev.da, ev.k, ev.p, ev.lay.layer, ev.alive, ev.th, ev.Sa
    tr = np.concatenate([np.arange(da) * k + p + 1, np.arange(da) * k + p + 2])
    qt = float(th[tr] @ _solve_psd(_sub(Sa, tr), th[tr]))
    pt, zt = _chi2(qt, tr.size, ev.nu)
    if p_time_det > pt:
        pt, zt = p_time_det, _z_of_p(p_time_det) if p_time_det < 1.0 else 0.0
    p_rob = _robust_trend_p(ev.X, ebar, alive, p, theta)
    robust = ""
    if p_rob > pt:
        pt, zt = p_rob, _z_of_p(p_rob) if p_rob < 1.0 else 0.0
        robust = f"; p = {p_rob:.2g} against the inputs' own scatter, which counts the mean's misfit"
    zc_ = th[tr] / np.sqrt(np.maximum((Sa.diag() if isinstance(Sa, _Blocks) else np.diag(Sa))[tr], 1e-300))
    wi = int(np.argmax(np.abs(zc_)))
    return _row("time_drift", "time_map", pt, zt, float(np.max(np.abs(th[tr]))),
                f"the map at layer {l} moves over acquisition time: "
                f"{'additive' if wi < da else 'gain'} trend {th[tr][wi]:+.3g} per unit t at "
                f"{l}:{alive[wi % da]} (z = {zc_[wi]:.1f}{' against the noise alone' if robust else ''}; "
                f"chi2 z = {zt:.1f} over the layer{robust})", [alive[wi % da]])


def map_rows(ev: MapEvidence, models: dict, dW, se, theta, ebar, rows: list, p_shape: float):
    """The rows of the map of a layer with alive neurons (appended to ``rows``, whose shape row
    they may amend). No class is more significant than the omnibus deviation from the programmed
    map, nor than the map's deviation beyond the shape of z. Returns the :class:`MapChoice`
    (its ``choice`` "detector" where a detector's gains and offsets fit)."""
    mc = choose_map(ev, models, dW, se)
    p_free = shape_free_p(ev, rows, p_shape)

    def floor(pv):
        return max(pv, mc.p_omni, p_free if p_free is not None else 0.0)

    choice, p_time_det = mc.choice, 0.0
    if choice == "gain":
        rows.append(_gain_row(ev, mc, floor))
    elif choice == "transfer":
        rows.append(_transfer_row(ev, mc, floor))
    elif choice == "rows":
        row, p_time_det = _neuron_transfer_row(ev, mc, rows, floor)
        rows.append(row)
    if choice == "general" and ev.lay.hidden:
        row, p_tdet = _detector_row(ev, rows, floor)
        if row is not None:
            choice, p_time_det = "detector", p_tdet
            rows.append(row)
    if choice in ("bias", "gain+bias", "general"):
        rows.extend(_beyond_gain_rows(ev, mc, choice, models, floor))
    programmed = choice == "programmed"
    rows.append(_row("weight_error" if programmed else "_omnibus", "omnibus", mc.p_omni if programmed else 1.0,
                     mc.z_omni if programmed else 0.0, mc.rel,
                     f"the map at layer {ev.lay.layer} is the programmed one (p = {mc.p_omni:.2g})"))
    if ev.tt is not None:
        rows.append(time_map_row(ev, theta, ebar, p_time_det))
    return dataclasses.replace(mc, choice=choice)
