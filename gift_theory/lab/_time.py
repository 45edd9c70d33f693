"""Maps and gains that change over the acquisition: a slow wander of a gain, a drifting map.

The identification (:mod:`.identification`) already reads a straight-line trend of each layer's
map (additive per neuron, a gain) across the inputs' mean times and within the inputs' shots.
A laser whose intensity wanders over the campaign, or weights that drift (W + t D), do more:

* **wander** -- a gain shared by the layer's neurons that follows a smooth path in t, not a
  line: the path is read in a basis of :data:`MODES` cosines, cos(pi m t), m = 1..M (a period
  down to 2 / M of the campaign; the cosines have mean 0 over the campaign, so a fixed gain stays
  the map's);
* **map drift** -- the whole map moving, each neuron's row and bias on its own: W_eff(t) =
  W_eff + t D, b_eff(t) = b_eff + t c (a drift beyond a gain).

Each is read twice, where each acquisition order shows it:

* *within the inputs' shots* (random or interleaved order: an input's shots spread over the
  campaign): each shot's residual less its input's mean -- with taps also less its regression on
  the shot's own input, by Frisch and Waugh, so a drift upstream that moves the layer's input is
  not read as this layer's -- against the time columns treated the same way. The score's
  covariance is the sum over the inputs of their shots' covariance (the neurons' noise, each
  input's own): the within-input residuals carry no misfit of the mean, so no law is assumed;
* *across the inputs' means* (blocked order: each input acquired in one go): each input's mean
  residual at the map fitted without the time terms, against the time columns with the map's
  own columns projected out, neuron by neuron (the map can take any fixed part of them). For the
  wander each input's contribution to the score is one draw, and Hotelling's T^2 over the inputs
  tests their mean -- valid for any misfit of the mean that does not go with the acquisition
  order (a saturating readout's curve enters at random), as
  ``identification._trend._robust_trend_p`` does for the straight line.

The two p-values are combined by Bonferroni (the smaller, doubled). The map drift is tested
neuron by neuron (an F test of its p + 1 coefficients: the shots' own sandwich within, one
residual scale per neuron across), Bonferroni over the neurons. Each cell weighs by its variance
moderated towards the model's variance of the cell (:func:`_moderated`).

**Put into the model.** A test below :data:`PUT_P` puts its reading into the map as a known term
of each shot's pre-activation (``_Layer.offset``), estimated from both readings at once (their
normal equations summed, each weighted by its noise): the wander's path times the weighted sum
u = W a, the drift's t (D a + c), less the part the map's own straight lines take
(:func:`_trends_left`). The map is then read at t = 0, and a drift's time average is not read as
a fixed weight error.

**Slow, or shot to shot.** A gain that fluctuates on a time scale shorter than the campaign has
a realised path with slow components too. The wander's row carries ``share``: the variance of
its fitted path within the inputs' shots over the gain's variance the shared-gain covariance
measures (``identification._noise``); below ``identification._trend.TREND_SHARE`` the mechanisms list puts
gain_fluctuation before time_drift (:func:`~gift_theory.lab._mechanisms._fluctuation_before_trend`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

#: cosines of the wander's basis, cos(pi m t), m = 1..MODES
MODES = 6
#: a test below this p puts its reading into the map (a known term of the pre-activation)
PUT_P = 1e-3
#: a reading is taken where the times spread by this much (sd): within the inputs' shots
#: (random or interleaved order), across the inputs' mean times (blocked order)
SPREAD = 0.05
#: the wander is put into the model when its slow modes carry at least this share of a wider
#: band's fitted path (else the gain fluctuates faster than a wander)
SLOW_SHARE = 0.5
#: the estimates leave directions whose information is below this share of the largest at 0
RCOND = 1e-6
#: the map drift is read on layers with at most this many parameters per neuron (a wider
#: layer's per-neuron columns, n r (p + 1) floats each, and their T^2 need many more inputs)
MAP_MAX = 65


@dataclasses.dataclass(frozen=True)
class Slow:
    """What :func:`slow_terms` found: the rows (class time_drift, tests ``wander`` and
    ``map_drift``) and the known term of the pre-activation to put into the map (n, r, d), or None."""

    rows: tuple
    offset: np.ndarray | None
    #: (d, p + 1, p + 1) the error the map drift's estimate puts into the map at t = 0, or None
    cov: np.ndarray | None = None


def basis(t, modes: int = MODES, first: int = 1) -> np.ndarray:
    """cos(pi m t), m = first..first + modes - 1, each less its least-squares line on [0, 1] (the
    straight-line trend is the map's own time columns' job): t.shape + (modes,)."""
    m = np.arange(first, first + modes)
    # L2 projection of cos(pi m t) on 1 and t - 1/2 over [0, 1]: 0 and 12 ((-1)^m - 1) / (pi m)^2
    slope = 12.0 * ((-1.0) ** m - 1.0) / (np.pi * m) ** 2
    tt = np.asarray(t, np.float64)[..., None]
    return np.cos(np.pi * tt * m) - slope * (tt - 0.5)


def _wald(C, e, w, dof_used: int = 0):
    """A Wald test of beta = 0 in e = C beta + error, the inputs independent, the error's
    covariance within an input free (the sandwich over the inputs, HC1).

    C (n, m, q) each input's m observations' columns, e (n, m) their residuals, w (n, m) their
    weights (inverse variances); ``dof_used`` (k): parameters per observation the residuals were
    fitted with before (the map's columns, read off the same inputs' means: the residuals are
    smaller than the errors by n / (n - k), and the meat with them -- without it the across
    reading rejected 4 of 48 null layers at 0.01). The p-value is Hotelling's T^2 of the
    inputs' scores, n - k of them. Returns (p, B, S, M): B = sum C^T w C and
    S = sum C^T w e, the normal equations, and M the sandwich's meat (summed by a caller that
    combines readings)."""
    n, _, q = C.shape
    Cw = C * w[:, :, None]
    B = np.einsum("nmq,nmk->qk", Cw, C)
    S = np.einsum("nmq,nm->q", Cw, e)
    Bi = np.linalg.pinv(B, rcond=1e-10)
    psi0 = np.einsum("nmq,nm->nq", Cw, e)  # each input's score at beta = 0
    psi = psi0 - np.einsum("nmq,nmk,k->nq", Cw, C, Bi @ S)  # ... and at the estimate
    w_, U = np.linalg.eigh(B)
    U = U[:, w_ > 1e-10 * max(float(w_.max()), 1e-300)]  # the directions the columns span
    rank = U.shape[1]
    dof = n - dof_used - rank
    M = psi.T @ psi * (n / max(dof, 1))
    ne = n - dof_used  # the inputs' scores, less what the residuals' earlier fit took
    if rank == 0 or dof < 2 or ne - rank < 2:
        return 1.0, B, S, M
    # Hotelling's T^2 of the scores' mean (their covariance about it, scaled as the residuals
    # are): a Wald statistic whose meat is read at the estimate ran small at 40 inputs and 6
    # columns (0.10 of Gaussian null sets below 0.05); T^2 is exact for Gaussian scores and
    # errs on the safe side for heavier tails
    dev = psi0 - psi0.mean(0)
    Spsi = dev.T @ dev / (n - 1) * (n / ne)
    mbar = psi0.mean(0) @ U
    T2 = float(n * mbar @ np.linalg.pinv(U.T @ Spsi @ U, rcond=1e-10) @ mbar)
    return float(stats.f.sf(T2 * (ne - rank) / ((ne - 1) * rank), rank, ne - rank)), B, S, M


def _ftest(C, e, w, dof_used: int, robust: bool = False, lev0: float = 0.0):
    """The classical F test of beta = 0 in e = C beta + error, the errors independent with
    variance 1 / w up to one common scale estimated from the residuals (one number, not a q x q
    covariance: with tens of coefficients per neuron and a hundred inputs a sandwich over the
    inputs is noise). C (N, q), e (N,), w (N,); ``dof_used``: degrees of freedom the residuals
    lost before (the inputs' means, a regression on the shot's own input, the map's columns).

    ``robust``: the observations' own sandwich instead of the common scale (HC3: each residual
    over one less its leverage, ``lev0`` added to each: the leverage of what the residuals were
    fitted with before, 1 / r for the inputs' means), for the within reading's thousands of
    shots. A neuron saturated on most shots has columns (its slope times t a) that live on the few
    shots near its linear range, where the map's misfit is too: one scale for all shots read that
    misfit as a drift (a null file's neuron at p = 1e-32). Returns (p, B, S, M) as :func:`_wald` (M: the estimate's
    meat -- B times the residuals' scale, or the sandwich's)."""
    Cw = C * w[:, None]
    B = Cw.T @ C
    S = Cw.T @ e
    Bi = np.linalg.pinv(B, rcond=RCOND)
    beta = Bi @ S
    res = e - C @ beta
    w_ = np.linalg.eigvalsh(B)
    rank = int(np.sum(w_ > RCOND * max(float(w_.max()), 1e-300)))
    dof = e.size - dof_used - rank
    if rank == 0 or dof < 5:
        return 1.0, B, S, B
    if robust:
        lev = lev0 + np.einsum("nq,qk,nk->n", Cw, Bi, C)
        u = w * res / np.maximum(1.0 - lev, 1e-3)
        M = (C * u[:, None]).T @ (C * u[:, None])
        V = Bi @ M @ Bi
        stat = float(beta @ np.linalg.pinv(V, rcond=RCOND) @ beta)
        return float(stats.f.sf(stat / rank, rank, dof)), B, S, M
    scale = float(np.sum(w * res * res)) / dof
    F = float(beta @ B @ beta) / rank / max(scale, 1e-300)
    return float(stats.f.sf(F, rank, dof)), B, S, B * scale


def _within_fw(C, g, A):
    """Within-input parts of the columns C (n, r, d, c): centred within the inputs and, with taps
    (``A`` (n, r, p) varying within an input), each neuron's column less its regression on the
    within-input deviations of g_i a (the shot's own input, linearised), pooled over the inputs."""
    C = C - C.mean(1, keepdims=True)
    if A is None:
        return C
    n, r, d, c = C.shape
    out = np.empty_like(C)
    for i in range(d):
        Gi = g[:, :, i, None] * A
        Gi = (Gi - Gi.mean(1, keepdims=True)).reshape(n * r, -1)
        Ci = C[:, :, i, :].reshape(n * r, c)
        beta = np.linalg.solve(Gi.T @ Gi + 1e-12 * np.eye(Gi.shape[1]), Gi.T @ Ci)
        out[:, :, i, :] = (Ci - Gi @ beta).reshape(n, r, c)
    return out


def _coefficients(T, X):
    """Per neuron, the least-squares coefficients (d, k, c) of T (n, d, c) on the map's columns
    X (n, d, k)."""
    Xn = X.transpose(1, 0, 2)
    G = np.linalg.pinv(np.matmul(Xn.transpose(0, 2, 1), Xn))
    return np.matmul(G, np.matmul(Xn.transpose(0, 2, 1), T.transpose(1, 0, 2)))


def _project_off(T, X):
    """Per neuron, T (n, d, c) less its least-squares projection on the map's columns X (n, d, k)."""
    return T - np.matmul(X.transpose(1, 0, 2), _coefficients(T, X)).transpose(1, 0, 2)


def _combine(readings):
    """Bonferroni over the readings taken: (p, B, S, M), the normal equations and meat of those
    taken summed."""
    taken = [r_ for r_ in readings if r_ is not None]
    if not taken:
        return 1.0, None, None, None
    p = float(min(1.0, len(taken) * min(r_[0] for r_ in taken)))
    return p, sum(r_[1] for r_ in taken), sum(r_[2] for r_ in taken), sum(r_[3] for r_ in taken)


def _moderated(obs, r: int, prior=None):
    """Each cell's variance (n, d), from its r shots, moderated towards its neuron's -- or, with
    ``prior``, towards the model's shape of it -- by an empirical Bayes prior over the inputs
    (Smyth 2004): (d0 s0^2 + (r - 1) s^2) / (d0 + r - 1), with s0^2 and the prior's degrees of
    freedom d0 read from the spread of log s^2 beyond what r - 1 degrees of freedom give (d0
    infinite -- the neuron's one variance -- where the spread is no wider).

    Weights 1 / s^2 from a handful of shots are heavy-tailed (an inverse chi-square of r - 1
    degrees of freedom): a few inputs carry the weighted sums, and an F test that counts every
    input's degree of freedom rejected far too often (a null file's map drift at p = 1e-4, raw
    p below 0.01 on 10 of 60 null files at 8 shots).

    ``prior`` (n, d): the model's variance of each cell, whose shape over the inputs the prior
    then takes (s0^2 times it: the ratio s^2 / prior is what is moderated). A hidden neuron's
    variance follows its slope, small where it saturates; towards one value per neuron its
    linear range, where the drift's columns live, weighed too much, and the map drift's F
    statistic averaged 1.29 on layer 1 of null files (1.11 with the model's shape)."""
    from scipy import special

    if prior is not None:
        prior = np.maximum(prior, 1e-300)
        return _moderated(obs / prior, r) * prior
    nu = max(r - 1, 1)
    z = np.log(np.maximum(obs, 1e-300)) - special.digamma(nu / 2) + np.log(nu / 2)
    zbar = z.mean(0)
    extra = z.var(0, ddof=1) - special.polygamma(1, nu / 2) if obs.shape[0] > 1 else np.zeros(obs.shape[1])
    out = np.empty_like(obs)
    for i in range(obs.shape[1]):
        if not np.isfinite(extra[i]) or extra[i] <= 1e-6:
            out[:, i] = np.exp(zbar[i])  # no spread beyond the sampling's: the neuron's one variance
            continue
        d0 = 2.0 * _trigamma_inverse(float(extra[i]))
        s0 = np.exp(zbar[i] + special.digamma(d0 / 2) - np.log(d0 / 2))
        out[:, i] = (d0 * s0 + nu * obs[:, i]) / (d0 + nu)
    return out


def _trigamma_inverse(y: float) -> float:
    """x with trigamma(x) = y (Newton's steps from Smyth's start, as limma's trigammaInverse)."""
    from scipy import special

    if y > 1e7:
        return 1.0 / np.sqrt(y)
    if y < 1e-6:
        return 1.0 / y
    x = 0.5 + 1.0 / y
    for _ in range(50):
        tri = special.polygamma(1, x)
        dif = tri * (1.0 - tri / y) / special.polygamma(2, x)
        x = x + dif
        if -dif / x < 1e-8:
            break
    return float(x)


def _solve(B, S):
    """The estimate where the data speak (a pseudo-inverse: directions the readings leave
    undetermined -- a straight line the map's own columns take -- are left at 0)."""
    return np.linalg.pinv(B, rcond=RCOND) @ S


@dataclasses.dataclass(frozen=True)
class _Reads:
    """What the wander and the map drift of one layer are read from (see :func:`slow_terms`):
    the within-input residuals ``e`` (n, r, d) less their input's mean, the inputs' mean residuals
    ``ebar``, each cell's variance ``obs`` (moderated: :func:`_moderated`), the slope ``g``, the
    shot's own input ``G`` (taps) or None, the map's design ``X``, the times ``t`` and which
    readings are taken (``use_w`` within the inputs' shots, ``use_a`` across their means)."""

    e: np.ndarray
    ebar: np.ndarray
    obs: np.ndarray
    g: np.ndarray
    G: np.ndarray | None
    X: np.ndarray
    t: np.ndarray
    use_w: bool
    use_a: bool


def _wander(rd: _Reads, u, layer: int, row_of):
    """The gain's wander: one path shared by the neurons, beyond a straight line. Returns (row,
    the known term to put into the map or None, the residuals ``e`` and ``ebar`` beyond it)."""
    n, r, d = rd.e.shape
    e, ebar, g, G, X = rd.e, rd.ebar, rd.g, rd.G, rd.X
    wdir = g * u  # how the layer's shots move with a gain on its weighted sum
    wts = np.broadcast_to((1.0 / rd.obs)[:, None, :], (n, r, d)).reshape(n, r * d)

    def wander(Phi):
        q = Phi.shape[-1]
        rw = ra = None
        if rd.use_w:
            C = _within_fw(Phi[:, :, None, :] * wdir[..., None], g, G)
            rw = _wald(C.reshape(n, r * d, q), e.reshape(n, r * d), wts) if n >= 3 * q + 3 else None
        if rd.use_a and n >= 3 * q + 3:
            Tt = _project_off(np.einsum("nrm,nrd->ndm", Phi, wdir) / r, X)
            ra = _wald(Tt, ebar, r / rd.obs, X.shape[2])
        return rw, ra

    Phi = basis(rd.t)
    rw, ra = wander(Phi)
    p_wander, Bw, Sw, _ = _combine([rw, ra])
    kappa = np.zeros(MODES) if Bw is None else _solve(Bw, Sw)
    path = Phi @ kappa  # (n, r): the gain's path beyond its mean and its straight line
    # slow or fast: the share of a wider band's fitted path that the slow modes carry (a gain
    # fluctuating within a few per cent of the campaign spreads over the band, a wander does not)
    Phi_f = basis(rd.t, 3 * MODES, first=MODES + 1)
    _, Bf, Sf, _ = _combine(wander(np.concatenate([Phi, Phi_f], axis=-1)))
    slow_share = 1.0
    if Bf is not None:
        both = np.concatenate([Phi, Phi_f], axis=-1) @ _solve(Bf, Sf)
        slow_share = float(np.var(path) / max(np.var(both), 1e-300))
    amp = float(np.sqrt(np.mean((path - path.mean()) ** 2)))
    pw, pa = (rw[0] if rw else 1.0), (ra[0] if ra else 1.0)
    row = dict(row_of("time_drift", "wander", p_wander, _z(p_wander), amp,
                      f"the gain of layer {layer} wanders over acquisition time beyond a straight line (a path "
                      f"in {MODES} cosines of t, rms {amp:.3g}; p = {pw:.2g} within the inputs' shots, "
                      f"{pa:.2g} across their means; the slow modes carry {slow_share:.0%} of a band three "
                      f"times wider)"),
               path_variance=float(np.mean((path - path.mean(1, keepdims=True)) ** 2)),
               path_rms=amp, slow_share=slow_share)
    offset = None
    if p_wander < PUT_P and slow_share >= SLOW_SHARE:
        if rd.use_a and not rd.use_w:
            # the inputs acquired one after the other: the path at the resolution the acquisition
            # gives, one gain per input (its mean residual along its gain direction, beyond the
            # path's mean: a fixed gain stays the map's) -- six cosines leave a wandering laser's
            # faster part in the inputs' means, read as a weight error
            wbar = wdir.mean(1)
            gam = np.sum(ebar * wbar, 1) / np.maximum(np.sum(wbar * wbar, 1), 1e-300)
            path = np.broadcast_to((gam - gam.mean())[:, None], (n, r))
        offset = path[:, :, None] * u
        # the map drift is read beyond the wander's fit
        e = e - _within_fw((path[:, :, None] * wdir)[..., None], g, G)[..., 0]
        ebar = ebar - np.mean(path[:, :, None] * wdir, axis=1)
    return row, offset, e, ebar


def _neuron_drift(rd: _Reads, A1, u1, i: int):
    """Neuron ``i``'s map drift (its row and bias linear in t) beyond its own gain and additive
    trend: (p, the estimate (p + 1,), its covariance)."""
    n, r, _ = rd.e.shape
    g, G, t, obs = rd.g, rd.G, rd.t, rd.obs
    k1 = A1.shape[2]
    p = k1 - 1
    tc = t - t.mean(1)[:, None]
    cols = g[:, :, i, None] * A1 * t[:, :, None]  # (n, r, k1): how the mean moves with D_i, c_i
    rw_i = ra_i = full_w = None
    if rd.use_w:
        # t less its input's mean time: the columns then have no part along the shot's own
        # slope and input that an input's mean time carries (the pooled regression on the
        # shot's own input leaves each input's part; where the map misfits a saturated
        # neuron that part correlates with the residual, and a null file's neuron read a
        # drift at p = 1e-32). Shots of one input are exchangeable in time without a drift:
        # these columns' score has mean 0 whatever the map's misfit.
        colc = g[:, :, i, None] * A1 * tc[:, :, None]
        Ci = _within_fw(colc[:, :, None, :], g[:, :, i:i + 1], G)[:, :, 0, :]
        # beyond this neuron's own gain and additive trends (the map's straight lines)
        Li = _within_fw(np.stack([g[:, :, i] * tc, g[:, :, i] * u1[:, :, i] * tc], -1)[:, :, None, :],
                        g[:, :, i:i + 1], G)[:, :, 0, :].reshape(n * r, 2)
        Cf = Ci.reshape(n * r, k1)
        Cb = Cf - Li @ np.linalg.lstsq(Li, Cf, rcond=None)[0]
        wi = np.broadcast_to(1.0 / obs[:, i, None], (n, r)).ravel()
        used = n + (p if G is not None else 0)  # the inputs' means, the shot's own input
        rw_i = _ftest(Cb, rd.e[:, :, i].ravel(), wi, used + 2, robust=True, lev0=1.0 / r)
        full_w = _ftest(Cf, rd.e[:, :, i].ravel(), wi, used)
    if rd.use_a:
        Tt = _project_off((cols.mean(1))[:, None, :], rd.X[:, i:i + 1, :])[:, 0, :]
        ra_i = _ftest(Tt, rd.ebar[:, i], r / obs[:, i], rd.X.shape[2])
    _, Bi, Si, Mi = _combine([full_w if rd.use_w else None, ra_i])
    Binv = np.linalg.pinv(Bi, rcond=RCOND)
    return _combine([rw_i, ra_i])[0], Binv @ Si, Binv @ Mi @ Binv


def _map_drift(rd: _Reads, lay, A, layer: int, row_of):
    """The map's drift: each neuron's row and bias, linear in t, beyond its own gain and additive
    trend. Returns (row, the known term to put into the map or None, its error's covariance at
    t = 0 or None)."""
    n, r, d = rd.e.shape
    p = A.shape[2]
    k1 = p + 1
    A1 = np.concatenate([A, np.ones((n, r, 1))], axis=2)  # (n, r, p + 1)
    u1 = np.broadcast_to(lay.A @ lay.W.T, (n, r, d))
    p_n = np.ones(d)
    Dm = np.zeros((d, k1))
    Dcov = np.zeros((d, k1, k1))
    if k1 <= MAP_MAX and (rd.use_w or rd.use_a) and n >= 3 * k1 + 3:
        for i in range(d):  # neuron by neuron: (n, r, p + 1) columns at a time
            p_n[i], Dm[i], Dcov[i] = _neuron_drift(rd, A1, u1, i)
    p_map = float(min(1.0, d * p_n.min()))
    worst = int(np.argmin(p_n))
    rel = float(np.sqrt(np.mean(Dm[:, :p] ** 2)) / max(np.sqrt(np.mean(lay.W ** 2)), 1e-300))
    row = row_of("time_drift", "map_drift", p_map, _z(p_map), rel,
                 f"the map of layer {layer} drifts over acquisition time beyond a gain and a shift of each "
                 f"neuron (W + t D, b + t c): rms D {rel:.2g} of rms W, most at {layer}:{worst} (p = "
                 f"{min(1.0, p_n[worst] * d):.2g}, Bonferroni over {d} neurons)", [worst])
    if p_map >= PUT_P:
        return row, None, None
    # the map at t = 0 carries the drift's error times the campaign's mean time
    return row, rd.t[:, :, None] * np.einsum("nrk,dk->nrd", A1, Dm), float(np.mean(rd.t)) ** 2 * Dcov


def slow_terms(lay, E, g, X, t, layer: int, row_of, within, var=None) -> Slow:
    """The wander and map-drift tests of one layer (see the module) and, for a test below
    :data:`PUT_P`, the known term to put into its map. ``var`` (n, r, d): the model's variance of
    each shot, the shape the cells' variances are moderated towards (:func:`_moderated`).

    lay : the identification's ``_Layer`` (A the regressor of each shot, Y, W, offset)
    E : (n, r, d) each shot's residual at the map fitted without these terms; g (n, r, d) the
        slope of the layer's mean at each shot; X (n, d, k) the map's design per input
    t : (n, r) acquisition times
    within : ``identification._stats._within`` (a residual less its regression on the shot's own input)
    row_of : ``identification._stats._row``
    """
    n, r, d = E.shape
    A = np.broadcast_to(lay.A, (n, r, lay.A.shape[2]))
    t = np.asarray(t, np.float64)
    G = A if lay.A.shape[1] > 1 else None  # with taps: the shot's own input varies within an input
    Ew = within(E, g, lay.A)
    # a cell of identical shots (a quantized readout) weighs as much as the layer's resolution
    # lets it, not 1 / 1e-300 (which overflowed the sandwich and stopped the identification)
    obs = np.maximum(np.var(Ew, axis=1, ddof=1), max(float(lay.res_var), 1e-300)) if r > 1 else np.ones((n, d))
    tbar = t.mean(1)
    if r > 2:
        obs = _moderated(obs, r, None if var is None else np.mean(var, axis=1))
    rd = _Reads(Ew - Ew.mean(1, keepdims=True), E.mean(1), obs, g, G, X, t,
                r > 2 and float(np.std(t - tbar[:, None])) >= SPREAD, float(np.std(tbar)) >= SPREAD)
    u = np.broadcast_to(lay.A @ lay.W.T, (n, r, d))
    wander_row, offset, e, ebar = _wander(rd, u, layer, row_of)
    drift_row, drift, cov = _map_drift(dataclasses.replace(rd, e=e, ebar=ebar), lay, A, layer, row_of)
    if drift is not None:
        offset = drift if offset is None else offset + drift
    if offset is not None and X.shape[2] == A.shape[2] + 3:
        offset = _trends_left(offset, g, X, u, tbar)
    return Slow((wander_row, drift_row), offset, cov)


def _trends_left(offset, g, X, u, tbar):
    """The known term less the part the map's own straight lines take (its trends, t_bar (c + k u)
    per neuron, the inputs' mean times): what is put in then leaves the map's trends their whole
    share of the data. Put in whole, a drift's estimate moved the map's trends by its own error
    along them -- noise the trends' covariance does not carry (a null file's trend read at
    p = 6e-12 by ``time_map``). The part along the map's columns at t = 0 stays: the map is
    read at t = 0 without the drift's time average."""
    p1 = X.shape[2] - 2
    h = np.mean(g * offset, axis=1)  # (n, d) how the term moves each input's mean, to first order
    coef = _coefficients(h[:, :, None], X)[:, :, 0]  # (d, k)
    return offset - tbar[:, None, None] * (coef[:, p1] + coef[:, p1 + 1] * u)


def add_cov(S, full: bool, cov, k: int) -> None:
    """Add the drift's error (d, p + 1, p + 1) to the map's covariance ``S`` (its W and b entries):
    the dense (d k, d k) matrix (``full``) or its per-neuron blocks (d, k, k)."""
    d, k1, _ = cov.shape
    for i in range(d):
        if full:
            S[i * k:i * k + k1, i * k:i * k + k1] += cov[i]
        else:
            S[i, :k1, :k1] += cov[i]


def _z(p: float) -> float:
    return float(stats.norm.isf(np.clip(p, 1e-300, 1.0)))


def attach_share(rows: list, noise_rows) -> None:
    """Give the wander's row its ``share``: its fitted path's variance within the inputs' shots over
    the gain's variance the shared-gain covariance test reads (``variance`` of its row)."""
    gain_var = next((r.get("variance") for r in noise_rows if r["test"] == "common_gain"), None)
    for r in rows:
        if r["test"] == "wander" and gain_var is not None and gain_var > 0:
            r["share"] = float(min(1.0, r["path_variance"] / gain_var))
            r["evidence"] += f"; the path carries {r['share']:.0%} of the gain's variance within the inputs' shots"


def residual_in_time(key, model, meas, bins: int = 40) -> dict:
    """What the diagnosis figures draw against acquisition time (needs ``meas.t``): per measured
    layer, each shot's residual from ``model``'s mean of its input (:data:`MODEL_SHOTS_FIGURE`
    model shots), read along the signal -- the shot's relative gain, sum_i e_i mu_i / sum_i mu_i^2
    (a gain that drifts or wanders moves it; a memory moves it with the shot before) -- in
    ``bins`` equal bins of t: ``{layer: {"t": centres, "mean": .., "se": ..}}``, plus the file's
    acquisition order (``"order"``: blocked or random). Empty without times."""
    from ._shots import model_shots

    if meas.t is None:
        return {}
    t = np.asarray(meas.t, np.float64)
    outs = model_shots(key, model, meas, MODEL_SHOTS_FIGURE)
    edges = np.linspace(t.min(), t.max() + 1e-12, bins + 1)
    which = np.clip(np.digitize(t.ravel(), edges) - 1, 0, bins - 1)
    out = {}
    for l, Y, M in zip(meas.layer_ids(), meas.layers(), outs):
        mu = np.asarray(M, np.float64).mean(1)  # (n, d)
        e = np.asarray(Y, np.float64) - mu[:, None, :]
        g = np.einsum("nrd,nd->nr", e, mu) / np.maximum(np.sum(mu * mu, 1), 1e-300)[:, None]
        g = g.ravel()
        cnt = np.bincount(which, minlength=bins).astype(float)
        m = np.bincount(which, g, minlength=bins) / np.maximum(cnt, 1)
        v = np.bincount(which, g * g, minlength=bins) / np.maximum(cnt, 1) - m * m
        out[int(l)] = {"t": 0.5 * (edges[1:] + edges[:-1]), "mean": m,
                       "se": np.sqrt(np.maximum(v, 0.0) / np.maximum(cnt - 1, 1)), "count": cnt}
    out["order"] = "blocked" if float(np.std(t.mean(1))) >= 0.1 else "random"
    return out


#: model shots per input behind the figure's means
MODEL_SHOTS_FIGURE = 64
