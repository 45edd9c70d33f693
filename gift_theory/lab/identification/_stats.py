"""The statistics the identification decides by: chi-square and F tails, per-input covariances
of the residuals, the sandwich covariance of the mean map, generalised least squares of restricted
maps, and the sample kurtosis of r shots."""

from __future__ import annotations

import numpy as np
from scipy import linalg, stats

#: layers whose stacked parameters exceed this are treated neuron by neuron (block-diagonal)
FULL_COV_MAX = 1600

#: directions of a design or covariance whose eigenvalue, after scaling to unit diagonal, is below
#: this share of the largest are not identified: float64 inverts them to rounding, not to data
IDENTIFIED_RTOL = 1e-10


def _z_of_p(p):
    return float(stats.norm.isf(np.clip(p, 1e-300, 1.0)))


def _chi2(q, df, nu=None):
    """(p, z) of a chi-square statistic; z unbounded (Wilson-Hilferty past float range).

    ``nu``: the degrees of freedom of the covariance the quadratic form was built with (a Wald
    statistic under an estimated covariance is Hotelling's T^2: referred to F(df, nu - df + 1)
    scaled by nu df / (nu - df + 1), not to a chi-square that would call its noise a signal)."""
    df = max(int(df), 1)
    if nu is not None and np.isfinite(nu):
        nu = max(float(nu), df + 10.0)
        p = float(stats.f.sf(q * (nu - df + 1) / (nu * df), df, nu - df + 1))
        if p > 1e-250:
            return p, _z_of_p(p)
        q = q * (nu - df + 1) / nu  # past float range, the scaled statistic on the chi-square's z
    else:
        p = float(stats.chi2.sf(q, df))
    if p > 1e-250:
        return p, _z_of_p(p)
    return p, float(((q / df) ** (1 / 3) - (1 - 2 / (9 * df))) / np.sqrt(2 / (9 * df)))


def _two_sided(z):
    return float(min(1.0, 2.0 * stats.norm.sf(abs(z))))


def _row(cls, test, p, z, effect, evidence, neurons=()):
    return {"class": cls, "test": test, "p": float(min(max(p, 0.0), 1.0)), "z": float(z), "effect": float(effect),
            "evidence": evidence, "neurons": tuple(int(i) for i in neurons)}


def _cell_cov(E):
    """Per input, the covariance across shots of the residuals (n, d, d) (ddof 1)."""
    r = E.shape[1]
    c = E - E.mean(1, keepdims=True)
    return np.einsum("nki,nkj->nij", c, c) / max(r - 1, 1)


def _cell_var(E, floor: float = 0.0):
    """Per input, the variance across shots of each neuron's residual (n, d) (ddof 1): the
    diagonal of :func:`_cell_cov` without its d^2 floats per input; at least ``floor`` (the
    layer's resolution: cells of identical shots weigh as much as the data can tell, not
    1 / 1e-300)."""
    v = np.var(E, axis=1, ddof=1) if E.shape[1] > 1 else np.zeros((E.shape[0], E.shape[2]))
    return np.maximum(v, floor)


def _within(E, g, A):
    """The residuals with their within-input part along the layer's own input removed.

    With taps a layer's regressor varies from shot to shot (its input's noise), and W_eff --
    read off the per-input means -- carries an error that moves the residuals within an input
    along g (a - mean a): the within-input variance would hold that error too (measured: +3 %
    at 60 inputs x 16 shots on a hidden layer of 12 inputs). Per neuron, the within-input
    deviations are regressed on g (a - mean a) (pooled over inputs) and the fit removed; the
    caller divides by the degrees of freedom left. Layer 1 (one regressor per input): unchanged."""
    if A.shape[1] == 1:
        return E
    n, r, d = E.shape
    p = A.shape[2]
    Ed = E - E.mean(1, keepdims=True)
    out = np.array(E, dtype=np.float64, copy=True)
    # neuron by neuron: the (n r, p) design of one neuron at a time (all at once it is d n r p
    # floats: 1.3 GB on a 100-neuron layer fed by 500 at 200 inputs x 16 shots)
    for i in range(d):
        Gi = g[:, :, i, None] * A  # (n, r, p)
        Gi = (Gi - Gi.mean(1, keepdims=True)).reshape(n * r, p)
        beta = np.linalg.solve(Gi.T @ Gi + 1e-12 * np.eye(p), Gi.T @ Ed[:, :, i].reshape(n * r))
        out[:, :, i] -= (Gi @ beta).reshape(n, r)
    return out


def _gram(X, w=None):
    """Per neuron ``sum_n w[n, i] X[n, i, p] X[n, i, q]`` as (d, k, k), by batched matrix
    products on strided views (BLAS takes the row stride; numpy's einsum of these indices runs
    its own loops, 2.3 times slower at 50 neurons x 400 inputs, and contiguous copies first
    cost 5-10 times the product)."""
    Xn = X.transpose(1, 0, 2)  # (d, n, k), a view
    return np.matmul(Xn.transpose(0, 2, 1), Xn if w is None else (X * w[:, :, None]).transpose(1, 0, 2))


def _meat(C, X):
    """sum_n C[n, i, j] X[n, i, p] X[n, j, q] as (d, k, d, k): batched matrix products over
    blocks of neurons i (an einsum over four indices ran at a tenth of BLAS' pace)."""
    n, d, k = X.shape
    out = np.empty((d, k, d, k))
    chunk = max(1, int(4e6 // max(n * d * k, 1)))
    for i0 in range(0, d, chunk):
        sl = slice(i0, min(i0 + chunk, d))
        Y = C[:, sl, :, None] * X[:, None, :, :]  # (n, c, d, k)
        c = Y.shape[1]
        out[sl] = np.matmul(X[:, sl, :].transpose(1, 2, 0),
                            Y.transpose(1, 0, 2, 3).reshape(c, n, d * k)).reshape(c, k, d, k)
    return out


def _covariance(X, Chat, obs, r, inv=None):
    """The sandwich covariance of the stacked per-neuron least squares (d (p+1) square), or
    its per-neuron blocks (d, p+1, p+1) when the layer is wide (``Chat``: per input the
    residuals' covariance across neurons, needed only then; ``obs`` its diagonal; ``r`` the
    shots a per-input mean averages); whether it is the full matrix; and the neurons whose map
    the data see only in part. ``inv``: the design Gram's :func:`_gram_inv` where the caller has
    it (the covariance holds the directions it sees)."""
    n, d, k = X.shape
    Binv, unseen = _gram_inv(_gram(X)) if inv is None else inv
    if d * k <= FULL_COV_MAX:
        meat = _meat(Chat / r, X)
        S = np.matmul(Binv, meat.transpose(2, 0, 1, 3))  # (j, i, a, c): Binv_i meat_ij
        S = np.matmul(S, Binv.transpose(0, 2, 1)[:, None])  # (j, i, a, d): ... Binv_j^T
        S = S.transpose(1, 2, 0, 3).reshape(d * k, d * k)
        return 0.5 * (S + S.T), True, unseen
    # Binv_i meat_i Binv_i^T per neuron (a three-operand einsum loops over all five indices:
    # d k^4 steps, hours on a 785-input layer; two batched products are 2 d k^3)
    T = np.matmul(Binv, _gram(X, obs / r))
    S = np.matmul(T, Binv.transpose(0, 2, 1))
    return 0.5 * (S + S.transpose(0, 2, 1)), False, unseen


def _scaled(S):
    """S scaled to unit diagonal: (the scaled matrix on the nonzero diagonal, the scale, its index)."""
    dg = np.diagonal(S)
    nz = np.flatnonzero(dg > 0)
    D = np.sqrt(dg[nz])
    return S[np.ix_(nz, nz)] / np.outer(D, D), D, nz


def _well_conditioned(Ss) -> bool:
    """Whether a unit-diagonal symmetric matrix is positive definite with reciprocal condition
    above :data:`IDENTIFIED_RTOL` (its Cholesky factor and LAPACK's estimate from it)."""
    if Ss.shape[0] == 0:
        return True
    try:
        c = linalg.cholesky(Ss, check_finite=False)  # upper
    except linalg.LinAlgError:
        return False
    rcond, info = linalg.lapack.dpocon(c, float(np.abs(Ss).sum(0).max()))
    return info == 0 and rcond > IDENTIFIED_RTOL


def _truncated(Ss):
    """The eigen-pseudo-inverse of a unit-diagonal symmetric matrix without the directions below
    :data:`IDENTIFIED_RTOL` of its largest eigenvalue (negative ones included): (it, the
    eigenvectors, which of them are kept)."""
    w, U = np.linalg.eigh(Ss)
    keep = w > IDENTIFIED_RTOL * max(float(w.max(initial=0.0)), 1e-300)
    return (U[:, keep] / w[keep]) @ U[:, keep].T, U, keep


def _gram_inv(G, N=None, share: float = 0.05):
    """Per neuron the inverse of its design's Gram (d, k, k), and the neurons whose map the data
    see only in part: {neuron: (its unseen entries (k,) bool, the projection (k, k) of its map's
    entries onto what the data identify)}.

    A neuron saturated at most inputs, or a layer whose inputs are collinear (zero pixels, inputs
    pinned at a rail), has directions of its map the data do not see: its Gram, scaled to unit
    diagonal, is singular to rounding (condition 1e15-1e17 on a tanh layer at s = 1), and its
    plain inverse is rounding noise that made the sandwich covariance indefinite. There the
    pseudo-inverse without those directions is used; an entry is unseen when a direction left
    out moves it, and the projection (the pseudo-inverse times the Gram) removes from a map's
    entries what the data cannot tell from zero.

    ``N`` (k, k): the Gram of the design's own error, where the regressor is a Monte Carlo mean
    (no taps). A direction whose error is more than ``share`` of the design's spread along it
    (the generalised eigenvalues of N against the Gram) is unseen too: the least squares reads
    the draws' noise there and shrinks the map towards 0 along it (three inputs through 21
    hidden neurons: W_eff = 0.37 W, gain_error named on a null file)."""
    d, k = G.shape[:2]
    Binv = np.linalg.inv(G + 1e-12 * np.eye(k))
    unseen = {}
    for i in range(d):
        Ss, D, nz = _scaled(G[i])
        well = _well_conditioned(Ss)
        drop = None
        if well and N is not None:
            mu, V = linalg.eigh(N[np.ix_(nz, nz)] / np.outer(D, D), Ss)  # V' Ss V = I
            drop = mu > share
            if not drop.any():
                drop = None
        if well and drop is None:
            if nz.size == k:
                continue
            inv, mask = np.linalg.inv(Ss), np.ones(k, bool)  # only inputs that are 0 at every input
            mask[nz] = False
        elif drop is not None:
            inv = V[:, ~drop] @ V[:, ~drop].T
            Vd = V[:, drop] / np.linalg.norm(V[:, drop], axis=0)
            mask = np.ones(k, bool)
            mask[nz] = np.sum(Vd ** 2, axis=1) > 1e-6
        else:
            inv, U, keep = _truncated(Ss)
            mask = np.ones(k, bool)
            mask[nz] = np.sum(U[:, ~keep] ** 2, axis=1) > 1e-6
        Binv[i] = 0.0
        Binv[i][np.ix_(nz, nz)] = inv / np.outer(D, D)
        unseen[i] = (mask, Binv[i] @ G[i])
    return Binv, unseen


def _psd_solve(S, v):
    """S^+ v for a covariance S and the rank it was inverted at: the plain solve where S, scaled to
    unit diagonal, is well conditioned; else the pseudo-inverse on the directions S identifies
    (those below :data:`IDENTIFIED_RTOL`, zero diagonals and negative rounding excluded)."""
    S = 0.5 * (S + S.T)
    Ss, D, nz = _scaled(S)
    if nz.size == S.shape[0] and _well_conditioned(Ss):
        return np.linalg.solve(S, v), S.shape[0]
    P, _, keep = _truncated(Ss)
    rank = int(keep.sum())
    x = np.zeros(np.shape(v))
    vs = np.asarray(v)[nz] / (D if np.ndim(v) == 1 else D[:, None])
    x[nz] = (P @ vs) / (D if np.ndim(v) == 1 else D[:, None])
    return x, rank


def _solve_psd(S, v):
    """S^+ v (:func:`_psd_solve` without the rank)."""
    return _psd_solve(S, v)[0]


def _wald(S, v):
    """The Wald statistic v' S^+ v and its degrees of freedom (the rank S is inverted at)."""
    x, rank = _psd_solve(S, v)
    return float(v @ x), rank


class _Blocks:
    """A block-diagonal covariance (one (k, k) block per neuron) of the stacked theta: what a wide
    layer's map has (dense, 100 neurons of 101 parameters were 10^4 x 10^4 floats and a solve of
    10^12 operations)."""

    def __init__(self, blocks):
        self.blocks = blocks
        self.k = blocks.shape[1]

    def sub(self, idx):
        """The dense covariance of the entries ``idx`` (a few hundred at most)."""
        i, a = np.divmod(np.asarray(idx), self.k)
        return np.where(i[:, None] == i[None, :], self.blocks[i[:, None], a[:, None], a[None, :]], 0.0)

    def diag(self):
        return np.einsum("iaa->ia", self.blocks).ravel()


def _sub(S, idx):
    return S.sub(idx) if isinstance(S, _Blocks) else S[np.ix_(idx, idx)]


def _gls(theta, S, R):
    """GLS of theta ~ N(R phi, S): phi, its covariance and the misfit chi-square."""
    if isinstance(S, _Blocks):
        d, k = S.blocks.shape[:2]
        Sinv = np.linalg.pinv(S.blocks, hermitian=True)
        Rb = R.reshape(d, k, R.shape[1])
        SiR = np.matmul(Sinv, Rb)
        F = np.einsum("iam,ian->mn", Rb, SiR)
        Fi = np.linalg.pinv(F)
        tb = theta.reshape(d, k)
        phi = Fi @ np.einsum("iam,ia->m", SiR, tb)
        q_full = float(np.einsum("ia,iab,ib->", tb, Sinv, tb))
        return phi, Fi, max(q_full - float(phi @ F @ phi), 0.0)
    return _gls_solved(theta, R, _solve_psd(S, np.column_stack([R, theta])))


def _gls_solved(theta, R, Si):
    """:func:`_gls` given S^-1 [R, theta] (one solve serves several R's sharing columns)."""
    Si_R = Si[:, :-1]
    F = R.T @ Si_R
    Fi = np.linalg.pinv(F)
    phi = Fi @ (Si_R.T @ theta)
    q_full = float(theta @ Si[:, -1])
    return phi, Fi, max(q_full - float(phi @ F @ phi), 0.0)


def _gls_all(theta, S, models: dict) -> dict:
    """:func:`_gls` for each restriction of ``models`` (name: R), the dense S solved once for
    all of them."""
    if isinstance(S, _Blocks):
        return {name: _gls(theta, S, R) for name, R in models.items()}
    Rs = list(models.values())
    Si = _solve_psd(S, np.column_stack(Rs + [theta]))
    out, c0 = {}, 0
    for name, R in models.items():
        m = R.shape[1]
        out[name] = _gls_solved(theta, R, np.column_stack([Si[:, c0:c0 + m], Si[:, -1]]))
        c0 += m
    return out


def _ag_z(b2, r: int):
    """Anscombe and Glynn's (1983) normalising transform of a sample kurtosis b2 = m4 / m2^2 of r
    values (r >= 5): near N(0, 1) for a normal sample (``scipy.stats.kurtosistest``'s statistic),
    its skewness 0.14 at r = 16 where b2's own is ~3. A mean over cells of b2 is dominated by
    its right tail, and a test over inputs of it was not calibrated at 80 inputs (the t-statistic
    of a skewed quantity: no-taps null files rejected at 0.01 on 5 % of random networks)."""
    b2 = np.asarray(b2, np.float64)
    E = 3.0 * (r - 1) / (r + 1)
    varb2 = 24.0 * r * (r - 2) * (r - 3) / ((r + 1) ** 2 * (r + 3) * (r + 5))
    x = (b2 - E) / np.sqrt(varb2)
    sb1 = 6.0 * (r * r - 5 * r + 2) / ((r + 7) * (r + 9)) * np.sqrt(6.0 * (r + 3) * (r + 5) / (r * (r - 2) * (r - 3)))
    A = 6.0 + 8.0 / sb1 * (2.0 / sb1 + np.sqrt(1.0 + 4.0 / sb1 ** 2))
    denom = 1.0 + x * np.sqrt(2.0 / (A - 4.0))
    term2 = np.sign(denom) * np.cbrt((1.0 - 2.0 / A) / np.maximum(np.abs(denom), 1e-300))
    return (1.0 - 2.0 / (9.0 * A) - term2) / np.sqrt(2.0 / (9.0 * A))


def _sample_law(x, r: int):
    """(2, ...): the sample excess kurtosis and its Anscombe-Glynn z of the r values along the
    last axis of ``x`` (r >= 5)."""
    x = x - x.mean(-1, keepdims=True)
    x = x * x  # squares (x ** 4 is a general power in numpy: 20 times slower than a square of squares)
    m2 = np.mean(x, -1)
    b2 = np.mean(x * x, -1) / np.maximum(m2 * m2, 1e-300)
    return np.stack([b2 - 3.0, _ag_z(b2, r)])


def _shots_law(shots, r: int):
    """(2, n, d): per input and neuron the mean of :func:`_sample_law` over the K // r samples of
    r consecutive shots of ``shots`` (n, K, d) -- a measurement's r shots (one sample) or a
    model's K."""
    n, K, d = shots.shape
    x = np.asarray(shots, np.float64)[:, :K // r * r].reshape(n, K // r, r, d)
    return _sample_law(np.moveaxis(x, 2, -1), r).mean(2)
