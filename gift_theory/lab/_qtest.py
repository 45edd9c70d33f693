"""Stage 3 of the lab: the discrepancy test on per-input channel values.

Inputs are independent, so per channel c the cell values over inputs give a Student t
statistic t_c (mean over its standard error); transformed to the normal scale, z_c. The
**discrepancy** is the one-sided chi-square-like sum::

    Q = sum_c max(z_c, 0)^2            (over every channel of every measured layer)

lower is better; a channel that a model gets wrong adds about n times its squared effect,
one it gets right adds noise only. Its distribution under the model follows from the
correlation of the channels across inputs (estimated from the same inputs): Q of
z ~ N(0, R), by Monte Carlo (2e4 draws, fixed seed; beyond the simulated range the
Satterthwaite tail of sum z^2 bounds it). That gives the **p-value** (the probability,
under the model, of a discrepancy at least as large) and **se** (the standard deviation
of Q under the model). A model with many fitted parameters is tested against a null that
allows for their estimation error (:func:`replicate_null`).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import special, stats

from .._finite import check_finite

#: Monte Carlo draws of the null distribution of Q (fixed seed: same data, same p-value)
NULL_DRAWS = 20_000


def log_variance_bias(dof) -> float:
    """E[log v] - log sigma^2 for the unbiased sample variance v of ``dof`` degrees of freedom of
    Gaussian shots: psi(dof / 2) - log(dof / 2) (about -1 / dof). Measured and model variances
    from different shot counts differ in log by the difference of two of these."""
    return float(special.digamma(dof / 2.0) - np.log(dof / 2.0))


def _z_scores(T, shift=None, extra_var=None):
    """Per column of T (n, C): the one-sided Student t, on the normal scale. Columns with
    no spread carry no information (z = 0). ``shift`` (C,) is subtracted from the column
    means and ``extra_var`` (C,) added to their squared standard errors (a null whose mean
    is not zero: see :func:`q_test`)."""
    n = T.shape[0]
    mean = T.mean(axis=0) - (0.0 if shift is None else shift)
    sd = T.std(axis=0, ddof=1)
    ok = sd > 1e-12 * (np.abs(mean) + 1e-300)
    se = np.sqrt(np.where(ok, sd, 1.0) ** 2 / n + (0.0 if extra_var is None else extra_var))
    t = np.where(ok, mean / se, 0.0)
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        z = stats.norm.isf(stats.t.sf(t, df=n - 1))
    z = np.where(np.isfinite(z), z, t)  # far in the tails the t and normal scales agree to the reported digits
    return z, ok


def replicate_null(T_reps):
    """``(shift, extra_var)`` of :func:`q_test` from B replicate channel matrices (B, n, C)
    simulated under the null *with* the model's estimation: data from the fitted model as
    truth, parameters refitted on simulated fitting data, channels on simulated held-out
    data. ``shift`` is the replicates' mean channel value (what estimation error alone
    adds); ``extra_var`` is the part of the variance of a channel's mean that inputs do not
    average away (an estimation error is shared by every held-out input), over and above
    the within-inputs standard error, inflated by 1 + 1/B for the estimated shift."""
    T_reps = np.asarray(T_reps, np.float64)
    B, n = T_reps.shape[:2]
    means = T_reps.mean(axis=1)  # (B, C)
    shift = means.mean(axis=0)
    within = np.mean(T_reps.var(axis=1, ddof=1), axis=0) / n
    between = means.var(axis=0, ddof=1) if B > 1 else np.zeros_like(shift)
    extra = np.maximum(between - within, 0.0) * (1.0 + 1.0 / B) + within / B
    return shift, extra


@functools.lru_cache(maxsize=16)
def _null_normals(C: int) -> np.ndarray:
    """The standard normal draws (NULL_DRAWS, C) of the null simulation: seed 0, made once per C."""
    G = np.random.default_rng(0).standard_normal((NULL_DRAWS, C))
    G.flags.writeable = False
    return G


def q_test(T, shift=None, extra_var=None):
    """The discrepancy test on per-input channel values T (n, C).

    ``shift`` and ``extra_var`` (C,) describe a null under which the channel means are not
    zero (a model with many fitted parameters scored on held-out inputs: its estimation
    error raises the mean-sensitive channels; :func:`replicate_null`).

    Returns
    -------
    Q, p_value, null_mean, null_sd, z (C,)
    """
    check_finite(T, "the discrepancy test's channel values (model shots against measured shots, per input)")
    z, ok = _z_scores(T, shift, extra_var)
    Q = float(np.sum(np.maximum(z, 0.0) ** 2))
    Tk = T[:, ok]
    if Tk.shape[1] == 0 or T.shape[0] < 3:
        return Q, 1.0, 0.0, 0.0, z
    R = np.atleast_2d(np.corrcoef(Tk, rowvar=False))
    lam, V = np.linalg.eigh(R)
    lam = np.clip(lam, 0.0, None)
    G = _null_normals(len(lam)) @ (V * np.sqrt(lam)).T
    Qs = np.sum(np.maximum(G, 0.0) ** 2, axis=1)
    exceed = int(np.sum(Qs >= Q))
    if exceed > 0:
        p = (1 + exceed) / (NULL_DRAWS + 1)
    else:  # beyond the simulation: Q <= sum z^2, whose tail is Satterthwaite's a chi2_b
        tr1, tr2 = float(np.sum(lam)), float(np.sum(lam ** 2))
        p = min(max(float(stats.chi2.sf(Q * tr1 / tr2, df=tr1 * tr1 / tr2)), 1e-300), 1.0 / (NULL_DRAWS + 1))
    return Q, float(p), float(Qs.mean()), float(Qs.std(ddof=1)), z


def t_to_z(mean: float, se: float, df: int) -> float:
    """A Student t statistic on the normal scale (two-sided: the sign is kept)."""
    if not np.isfinite(se) or se <= 0:
        return 0.0 if mean == 0 else float(np.sign(mean)) * 40.0
    t = mean / se
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        z = float(stats.norm.isf(stats.t.sf(abs(t), df=df)))
    return float(np.sign(t) * (z if np.isfinite(z) else abs(t)))


def over_inputs(T, what: str = "per-input values of a test") -> float:
    """z of the mean of per-input values T (n,) against zero (Student t over inputs); NaN with
    fewer than 3 inputs. A non-finite value is never dropped: :class:`~gift_theory._finite.NotFinite`
    names ``what``."""
    T = np.asarray(T, np.float64)
    check_finite(T, what)
    if T.size < 3:
        return float("nan")
    return t_to_z(float(T.mean()), float(T.std(ddof=1) / np.sqrt(T.size)), T.size - 1)
