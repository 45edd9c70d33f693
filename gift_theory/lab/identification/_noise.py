"""The noise of a layer: its level, its dependence on the signal and on the input's energy, its law
(kurtosis at r shots against the model's own), its covariance across the neurons and its trends
over acquisition time."""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..._arch import NUMPY_ACTIVATIONS as _ACT
from .._level import ALPHA
from .._qtest import over_inputs
from .._smoothing import smoothed
from ._layers import _Layer
from ._stats import _chi2, _row, _shots_law, _solve_psd, _two_sided, _sample_law

def _expected_kurtosis(act: str | None, z, vz, s2: float, r: int):
    """Per input and neuron (2, n, d), ``z`` (n, d) or per shot (n, r, d): the mean sample excess kurtosis (m4 / m2^2 - 3 of r shots,
    as measured) and the mean of its Anscombe-Glynn z (:func:`_ag_z`) of
    sigma(z + sqrt(vz) xi) + s eta, xi and eta standard normal -- a Gaussian pre-activation noise
    bent by the activation plus the layer's own output noise; ``act`` None: z + sqrt(vz) xi, a
    Gaussian layer without activation -- by Monte Carlo, independent draws per cell (fixed seed).
    A sample's kurtosis is biased at r shots by -6/(r+1) for a normal law and by terms in the
    skewness for a bent one; both are here (the law's own kurtosis alone, by quadrature, left
    layer 1 of 12-24-12-6 flagged on 4 % of null files at 0.01)."""
    f = _ACT[act][0] if act is not None else None
    # z per shot (n, r, d): the regressor moves within the input (taps), and the cell's law is the
    # mixture of each shot's own, each shot's deviation standardised by its own variance as the
    # measured ones are (at s = 1 the law at the cell's mean z named noise_law on null files)
    per_shot = z.ndim == 3 and f is not None
    if z.ndim == 3:
        z = np.moveaxis(z, 1, 2) if per_shot else z.mean(1)
    n, d = z.shape[:2]
    # draws per cell: few are enough -- the Monte Carlo error is independent across inputs, so
    # the test over inputs counts it in its own variance (calibrated at any B, a little less
    # power at small B); 2e6 samples per layer keep it at ~0.1 s (3e7 took 4 s a layer)
    B = int(max(4, min(32, 2e6 / max(n * d * r, 1))))
    rng = np.random.default_rng(20261127)
    sd, s_ = np.sqrt(np.maximum(vz, 0.0)), np.sqrt(s2)
    out = np.empty((2, n, d))
    chunk = max(1, int(4e6 // max(d * B * r, 1)))
    for c0 in range(0, n, chunk):
        zc = z[c0:c0 + chunk, :, None, :] if per_shot else z[c0:c0 + chunk, :, None, None]
        sc = sd[c0:c0 + chunk, :, None, None]
        shape = zc.shape[:2] + (B, r)
        x = (f(zc + sc * rng.standard_normal(shape)) + s_ * rng.standard_normal(shape) if f is not None
             else sc * rng.standard_normal(shape))
        if per_shot:
            mk, _, vk = smoothed(act, zc, np.broadcast_to(sc * sc, zc.shape))
            x = (x - mk) / np.sqrt(vk + s2)
        out[:, c0:c0 + chunk] = _sample_law(x, r).mean(-1)
    return out


def _expected_kurtosis_signal(act: str | None, z, u, vz, var, r: int, signal: tuple):
    """:func:`_expected_kurtosis` of the residuals of a layer whose noise variance changes with
    the signal (``signal`` of :func:`_signal_variance`): each shot at its own pre-activation ``z``
    (n, r, d) -- with taps the input changes from shot to shot, and so does a shot's variance --
    the value v = sigma(z + sqrt(vz') xi) + s eta (``act`` None: z + sqrt(vz') xi) less its mean
    given z, plus a readout noise sqrt(q |v|) zeta (form "readout": shot noise, a scale mixture
    with tails of its own at equal variance) or with vz' = vz + m^2 u^2 (form "pre-activation",
    ``u`` (n, r, d) each shot's weighted sum: a Gaussian pre-activation of a larger variance);
    ``vz`` (n, d) the pre-activation's unit variance; ``var`` (n, r, d) the variance each measured
    shot was divided by (the model's at its level), each drawn shot divided by it too."""
    form, s2a, c1 = signal
    f = _ACT[act][0] if act is not None else None
    n, d = vz.shape
    z, u, var = (np.broadcast_to(a_, (n, r, d)) for a_ in (z, u, var))  # layer 1: one input per cell, r shots
    B = int(max(4, min(32, 2e6 / max(n * d * r, 1))))
    rng = np.random.default_rng(20261129)
    out = np.empty((2, n, d))
    chunk = max(1, int(4e6 // max(d * B * r, 1)))
    for c0 in range(0, n, chunk):
        zc = np.moveaxis(z[c0:c0 + chunk], 1, 2)[:, :, None, :]  # (c, d, 1, r): each shot its own z
        vc = vz[c0:c0 + chunk][:, :, None, None] + (c1 / s2a * np.moveaxis(u[c0:c0 + chunk], 1, 2)[:, :, None, :] ** 2
                                                    if form != "readout" else 0.0)
        sc = np.sqrt(s2a * np.maximum(vc, 0.0))
        shape = zc.shape[:2] + (B, r)
        if f is not None:
            v = f(zc + sc * rng.standard_normal(shape)) + np.sqrt(s2a) * rng.standard_normal(shape)
            x = v - smoothed(act, zc, sc * sc, var=False)[0]
        else:
            x = sc * rng.standard_normal(shape)
            v = zc + x
        if form == "readout":
            x = x + np.sqrt(c1 * np.abs(v)) * rng.standard_normal(shape)
        x = x / np.sqrt(np.maximum(np.moveaxis(var[c0:c0 + chunk], 1, 2)[:, :, None, :], 1e-300))
        out[:, c0:c0 + chunk] = _sample_law(x, r).mean(-1)
    return out


def _signal_variance(obs, vcell, absv, pre2, s2: float) -> tuple:
    """The layer's noise variance fitted as a function of the signal, ``(form, c0, c1)``: each
    cell's observed variance ``obs`` (n, d) against ``c0 vcell + c1 x`` by non-negative least
    squares relative to the model's ``s2 vcell``, x either the readout value's ``absv`` = E|v|
    (shot noise, form "readout") or the squared pre-activation signal ``pre2`` (a fluctuating
    gain on the weighted sum, form "pre-activation": a Gaussian pre-activation of a larger
    variance), whichever leaves the smaller residual. c0 is the additive level s^2 left."""
    from scipy.optimize import nnls

    w = 1.0 / np.maximum(s2 * vcell, 1e-300).ravel()
    y = obs.ravel() * w
    best = None
    for form, x in (("readout", absv), ("pre-activation", pre2)):
        A = np.stack([vcell.ravel() * w, np.asarray(x, np.float64).ravel() * w], axis=1)
        coef, res = nnls(A, y)
        if best is None or res < best[0]:
            best = (res, form, float(coef[0]), float(coef[1]))
    return best[1:]


def _level_and_signal_rows(lay: _Layer, l: int, E, obs, z, g, var, b_eff, s2: float):
    """The noise level and its error over inputs, and its variance against the neuron's own signal,
    the input's energy and the weighted sum. Returns (row, s, s_se, vcell, u, wg, rho, signal):
    ``signal`` the variance fitted to the signal (:func:`_signal_variance`) where it changes with
    it, else None."""
    n, r, d = E.shape
    vcell = (var / s2).mean(1)  # (n, d) unit variance of a cell
    u = (z.mean(1) - b_eff)  # the weighted sum
    wg = (g.mean(1) * u) if lay.hidden else u  # how the layer's output moves with a gain on it
    # the level: observed over unit variances of the cells; its error over inputs
    Tl = np.sum(obs - s2 * vcell, axis=1)
    s_lvl = float(np.sqrt(s2))
    s_se = float(np.sqrt(n * np.var(Tl, ddof=1)) / max(np.sum(vcell), 1e-300) / (2 * s_lvl))
    # variance against the neuron's own signal and the input's energy
    rho = obs / np.maximum(s2 * vcell, 1e-300) - 1.0
    own = np.abs(z).mean(1)
    own = own - own.mean(0)
    energy = np.sum(lay.A ** 2, axis=2).mean(1)
    energy = energy - energy.mean()
    z_own = over_inputs(np.sum(rho * own, 1))
    z_en = over_inputs(rho.mean(1) * energy) if np.std(energy) > 0 else 0.0
    # ... and the neuron's weighted sum |u| (a noise on the weighted sum, s (1 + beta |u|) or a
    # multiplicative gain's m^2 u^2: z = u + b, and a bias of either sign hides it from |z|)
    own_u = np.abs(u) - np.abs(u).mean(0) if lay.hidden else own
    z_u = over_inputs(np.sum(rho * own_u, 1)) if lay.hidden else 0.0
    zs_ = {"the neuron's own |z|": z_own, "the input's energy |a_{l-1}|^2": z_en, "the weighted sum |u|": z_u}
    which = max(zs_, key=lambda k: abs(zs_[k]))
    zi = abs(zs_[which])
    slope_own = float(np.sum(rho * own) / max(np.sum(own ** 2), 1e-300))
    p_signal = min(1.0, (3 if lay.hidden else 2) * _two_sided(zi))
    row = _row("input_dependent_noise", "variance", p_signal, zi,
               slope_own, f"the noise variance at layer {l} changes with {which} (z = {z_own:.1f} own "
               f"signal |z|, {z_u:.1f} weighted sum, {z_en:.1f} input energy)")
    # the law is tested at the variance the data show: where it changes with the signal (that
    # test rejects), against the model with that dependence fitted -- shot noise's variance
    # q |v| makes a scale mixture with tails of its own, and a pure shot-noise file was named
    # noise_law at z = 11 (kurtosis +0.44 at the output) beside input_dependent_noise
    # (signal: (form, the additive s^2 left, q of q |v| or m^2 of m^2 u^2 in the pre-activation);
    # a hidden layer's output moves by g u where its pre-activation moves by u, each shot's own u)
    signal = (_signal_variance(obs, vcell, np.abs(lay.Y).mean(1),
                               (((g if lay.hidden else 1.0) * (z - b_eff)) ** 2).mean(1), s2)
              if p_signal < ALPHA and lay.law is None else None)
    if signal is not None and (signal[1] <= 0.0 or signal[2] <= 0.0):
        signal = None
    return row, s_lvl, s_se, vcell, u, wg, rho, signal


def _law_row(lay: _Layer, act: str, l: int, E, z, var, b_eff, s2: float, vz, signal):
    """The noise's law: per cell the sample kurtosis and its normalising transform against the
    model's own law of r shots. Returns (row, excess kurtosis beyond the model's)."""
    n, r, d = E.shape
    kz, kurt, k_exp = 0.0, 0.0, np.full((n, d), -6.0 / (r + 1))
    if r >= 5:
        # per cell the sample kurtosis and its normalising transform; the model's own law of r
        # shots: an activation bends a Gaussian pre-activation noise into a law of its own
        # (layer 1: the input's noise through W as well; no taps: the hidden layers' noise
        # propagated), and a normal sample's kurtosis is biased by -6/(r+1) (before the model's
        # was subtracted: layer 1 of 12-24-12-6 flagged on 15 % of null files)
        if lay.basis is not None:  # the model covariance's components (kurtosis: no scale needed)
            dev = np.matmul(E - E.mean(1, keepdims=True), lay.basis)
        else:  # each neuron, a shot by its own variance
            dev = (E - E.mean(1, keepdims=True)) / np.sqrt(np.maximum(var, 1e-300))
        k_cell = _shots_law(dev, r)
        gauss = lambda: _expected_kurtosis(act if lay.hidden else None, z if lay.A.shape[1] > 1 else z.mean(1),
                                           s2 * vz, s2, r)
        if lay.law is not None:
            laws = [lay.law]
        elif signal is None:
            laws = [gauss()]
        else:
            # the variance fitted to the signal is itself an estimate: where the signal test
            # rejects by chance, the fit puts part of a constant variance on |v|, and its scale
            # mixture expects tails the shots do not have. So the law is named only where the
            # shots depart from both the Gaussian law at the model's variance and the law with the
            # fitted dependence -- an intersection-union test, at level alpha whichever holds
            laws = [gauss(), _expected_kurtosis_signal(act if lay.hidden else None, z, z - b_eff, vz,
                                                       var if lay.basis is None else np.ones_like(var), r, signal)]
        zs = [over_inputs((k_cell[1] - law[1]).mean(1)) for law in laws]
        k = int(np.argmin(np.abs(zs)))
        law, kz = laws[k], zs[k]
        k_exp = law[0]
        kurt = float(np.mean(k_cell[0] - k_exp))
        if len(laws) > 1 and k == 0:
            signal = None  # the shots are nearer the law without the fitted dependence: it is the one named
    row = _row("noise_law", "kurtosis", _two_sided(kz), abs(kz), kurt,
               f"excess kurtosis {kurt:+.2f} of the "
               + ("output's noise along its model covariance's eigenvectors" if lay.basis is not None
                  else "standardised shots") + f" at layer {l} beyond the model's "
               f"{float(np.mean(k_exp)) + 6.0 / (r + 1):+.2f} (0 for a Gaussian law; the model's: its Gaussian "
               f"noise bent by the activation" + (f", with the variance fitted to the signal ({signal[0]}: "
                                                  f"{signal[2]:.3g} {'|v|' if signal[0] == 'readout' else 'u^2'}"
                                                  f" on top of s = {np.sqrt(signal[1]):.3g})"
                                                  if signal is not None else "") + ")")
    return row, kurt


def _covariance_rows(lay: _Layer, l: int, obs, Chat_s, sub, g, wg, Czu_s, d: int):
    """The covariance across the layer's neurons within a shot beyond the model's, on the neurons
    ``sub``: along the signal (a gain fluctuating from shot to shot) and along all neurons alike or
    any pattern (correlated noise). Returns (rows, the relative gain variance it amounts to)."""
    n, r = obs.shape[0], lay.Y.shape[1]
    rows = []
    ds = len(sub)
    gain_var = 0.0
    gs, wgs, obs_s = g.mean(1)[:, sub], wg[:, sub], obs[:, sub]
    if ds > 1:
        off = 1 - np.eye(ds)
        # the model's off-diagonal pattern (layer 1, no taps: the unmeasured input noise through W),
        # its scale fitted (a level misjudged elsewhere must not look like a correlation)
        M = (gs[:, :, None] * (Czu_s - np.eye(ds)) * gs[:, None, :]) if lay.hidden else (Czu_s - np.eye(ds))
        M = np.broadcast_to(M, Chat_s.shape) * off
        mm = float(np.sum(M * M))
        Cm = (float(np.sum(Chat_s * M)) / mm) * M if mm > 0 else np.zeros_like(Chat_s)

        def along(w):
            w = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
            a = np.einsum("ni,nij,nj->n", w, (Chat_s - Cm) * off, w)
            b_ = np.einsum("ni,ni->n", w * w, obs_s)
            return over_inputs(a / np.maximum(b_, 1e-300)), w, a

        z_g, wn, a_g = along(wgs)
        # the relative gain variance that excess covariance amounts to: C_ij = v w_i w_j off the
        # diagonal (w: how the output moves with the gain), v by least squares over the inputs
        Cex = (Chat_s - Cm) * off
        ww = wgs[:, :, None] * wgs[:, None, :] * off
        gain_var = float(np.sum(Cex * ww) / max(np.sum(ww * ww), 1e-300))
        rows.append(dict(_row("gain_fluctuation", "common_gain", stats.norm.sf(z_g), z_g, z_g,
                              f"excess covariance along the signal at layer {l} (z = {z_g:.1f}): a gain shared by "
                              f"the neurons, fluctuating from shot to shot"), variance=gain_var))
        z1 = along(np.ones((n, ds)))[0]
        z_s = along(gs)[0] if lay.hidden else z1
        # any correlation beyond the signal's direction: the off-diagonal covariance, less a fitted
        # rank-one part along the signal, squared, beyond its null size
        # <Q, Q> = 1 - sum w^4 is 0 where the signal sits on one neuron (a saturated layer): no
        # off-diagonal part to fit there (a_g / 1e-300 overflowed)
        den = 1.0 - np.sum(wn ** 4, 1)
        alpha = np.where(den > 1e-12, a_g / np.where(den > 1e-12, den, 1.0), 0.0)
        dC = (Chat_s - Cm - alpha[:, None, None] * wn[:, :, None] * wn[:, None, :]) * off
        # The rank-one part fitted per input, alpha Q with Q = w w^T off the diagonal, absorbs
        # its share of the sampling error e of the off-diagonal covariance: what is left has
        # expectation sum_{i != j} E e_ij^2 - E <e, Q>^2 / <Q, Q>, and for r shots of covariance
        # C (Wishart) E e_ij^2 = (C_ii C_jj + C_ij^2) / (r - 1), E <e, Q>^2 = 2 tr(Q C Q C) / (r - 1)
        # -- the pairs' errors are correlated, strongly where a narrow layer upstream makes the
        # output's noise nearly low-rank, and the projection takes more than its one pair's
        # worth there (U's mean -0.19 on a 12-output null file after a 4-neuron layer; without
        # any of this, z = -2.5 on average over 60 random null networks, and no power). A layer
        # of two neurons has nothing left (not tested).
        Cfull = Cm + obs_s[:, :, None] * np.eye(ds)
        Q = wn[:, :, None] * wn[:, None, :] * off
        QQ = np.maximum(np.sum(Q * Q, axis=(1, 2)), 1e-300)

        def expected_left(C, dof):
            v = np.diagonal(C, axis1=-2, axis2=-1)
            total = np.sum((v[:, :, None] * v[:, None, :] + C ** 2) * off, axis=(1, 2))
            QC = Q @ C
            return (total - 2.0 * np.einsum("nij,nji->n", QC, QC) / QQ) / dof

        left = expected_left(Cfull, max(r - 1, 1))
        if lay.draws > 1 and not lay.hidden:
            # without taps the model's covariance is a Monte Carlo estimate too, its own error
            # part of dC's: M draws of the hidden layers' propagated part H of the output's
            # covariance (its diagonal h; the output's own noise is exact, and counting it here
            # too put U's mean at -0.09 on a 9-output null file)
            h = np.broadcast_to((float(np.sum(Chat_s * M)) / mm if mm > 0 else 0.0)
                                * (np.diagonal(Czu_s, axis1=-2, axis2=-1) - 1.0), obs_s.shape)
            left = left + expected_left(Cm + h[:, :, None] * np.eye(ds), lay.draws - 1)
        elif lay.draws > 1:
            left = left * (1.0 + max(r - 1, 1) / (lay.draws - 1))
        U = (np.sum(dC ** 2, axis=(1, 2)) - left) / np.maximum(left, 1e-300)
        z_u = over_inputs(U) if ds > 2 else -np.inf
        zc_ = max(z1, z_s, z_u)
        what = ("along all neurons alike (common additive noise)" if zc_ == z1 else
                "along sigma'(z) (common noise before the activation)" if zc_ == z_s else
                "in a pattern beyond the signal's direction")
        rows.append(dict(_row("correlated_noise", "correlation", min(1.0, 3 * stats.norm.sf(zc_)), zc_, zc_,
                              f"noise correlated across the neurons of layer {l} {what} (z = {z1:.1f} common"
                              + (f", {z_u:.1f} any pattern)" if ds > 2 else ")")
                              + (f"; read on {ds} of its {d} neurons" if ds < d else "")),
                         z_common=float(z1), z_pattern=float(z_u) if ds > 2 else None))
    return rows, gain_var


def _time_within_row(l: int, t, E, E_time, sub, g, u, Chat_s, gain_var: float):
    """Trends within an input's shots (acquisition order interleaved across inputs): the
    within-input residuals against t less its input's mean, additive per neuron and a gain."""
    ds = len(sub)
    # trends within an input's shots (acquisition order interleaved across inputs): the
    # within-input residuals against t - its input's mean, additive per neuron and a gain
    tw = t - t.mean(1, keepdims=True)
    Es = (E if E_time is None else E_time)[:, :, sub]
    Ed = Es - Es.mean(1, keepdims=True)
    gk = np.broadcast_to(g[:, :, sub], Es.shape)
    rows_t = []
    for name, D in (("additive", gk * tw[:, :, None]), ("gain", gk * np.broadcast_to(u[:, None, sub], Es.shape)
                                                          * tw[:, :, None])):
        S_ = np.sum(D * D, axis=(0, 1))
        beta = np.sum(D * Ed, axis=(0, 1)) / np.maximum(S_, 1e-300)
        MD = np.einsum("nki,nkj->nij", D, D)
        Cb = np.einsum("nij,nij->ij", MD, Chat_s) / np.maximum(np.outer(S_, S_), 1e-300)
        if name == "additive":
            q = float(beta @ _solve_psd(Cb, beta))
            rows_t.append((name, *_chi2(q, ds), beta, Cb))
        else:  # one relative gain trend shared by the neurons: the precision-weighted mean
            wv = 1.0 / np.maximum(np.diag(Cb), 1e-300)
            wv = wv / wv.sum()
            kb = float(wv @ beta)
            zk = kb / np.sqrt(max(float(wv @ Cb @ wv), 1e-300))
            rows_t.append((name, _two_sided(zk), abs(zk), beta, Cb))
    best = min(rows_t, key=lambda x: x[1])
    zc_ = best[3] / np.sqrt(np.maximum(np.diag(best[4]), 1e-300))
    wi = int(np.argmax(np.abs(zc_)))
    row = _row("time_drift", "time_within", min(1.0, 2 * best[1]), best[2], float(best[3][wi]),
               f"within the inputs' shots, layer {l} moves with acquisition time: {best[0]} trend "
               f"{best[3][wi]:+.3g} per unit t at {l}:{int(sub[wi])} (z = {zc_[wi]:.1f}; the layer's "
               f"z = {best[2]:.1f})", [int(sub[wi])])
    if best[0] == "gain" and ds > 1 and gain_var > 0:
        # how much of the gain's variance within an input's shots the trend carries: a drift
        # carries all of it, a gain fluctuating on a time scale shorter than the campaign
        # (an AR(1) laser) little -- its realised path has a trend too
        wv = 1.0 / np.maximum(np.diag(best[4]), 1e-300)
        kb = float((wv / wv.sum()) @ best[3])
        share = min(1.0, kb * kb * float(np.mean(tw * tw)) / gain_var)
        row = dict(row, share=share, evidence=row["evidence"] + f"; the trend carries {share:.0%} of the "
                   "gain's variance within the inputs' shots")
    return row


def _noise_rows(lay: _Layer, act: str, l: int, t, E, obs, Chat_s, sub, z, g, var, b_eff, s2: float, vz, Czu_s,
                E_time=None):
    """The noise's tests at one layer from the within-input residuals ``E`` (n, r, d) and their
    variances ``obs`` (n, d); the covariance across neurons ``Chat_s`` on the neurons ``sub``
    (with the model's unit covariance ``Czu_s`` there); ``var`` the model's variance of each
    shot, ``vz`` the unit variance of the pre-activation noise (n, d). Returns (rows, s, s_se,
    excess kurtosis beyond the model's)."""
    n, r, d = E.shape
    row, s_lvl, s_se, vcell, u, wg, rho, signal = _level_and_signal_rows(lay, l, E, obs, z, g, var, b_eff, s2)
    rows = [row]
    row, kurt = _law_row(lay, act, l, E, z, var, b_eff, s2, vz, signal)
    rows.append(row)
    cov_rows, gain_var = _covariance_rows(lay, l, obs, Chat_s, sub, g, wg, Czu_s, d)
    rows.extend(cov_rows)
    if t is not None and r > 2 and np.std(t - t.mean(1, keepdims=True)) > 0:
        rows.append(_time_within_row(l, t, E, E_time, sub, g, u, Chat_s, gain_var))
    if t is not None and np.std(t.mean(1)) > 0:
        tc = t.mean(1) - t.mean()
        z_vt = over_inputs(tc * rho.mean(1))
        rows.append(_row("time_drift", "time_noise", _two_sided(z_vt), abs(z_vt), z_vt,
                         f"the noise level at layer {l} moves over acquisition time (z = {z_vt:.1f})"))
    return rows, s_lvl, s_se, kurt
