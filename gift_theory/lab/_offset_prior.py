"""Do fitted offsets look like their effect? The checks of the verdict's rule b.

A set of fitted offsets is accepted as the effect's N(0, e^2) draws only if it looks like
them: no gross outlier among them (:func:`outlier_test`, the neuron named), and for a weight
error no coupling to W beyond what independent draws show (:func:`coupling_test`).
:func:`prior_check` runs them on a fitted model, :func:`refusing` picks the rows that refuse.
"""

from __future__ import annotations


import numpy as np
from scipy import stats

from .._measurement import Measurement
from ._shots import Model
from ._offset_kinds import base_model, kinds_of
from ._offset_fit import offset_deltas


#: a normal-theory test refuses the fitted values beyond this |z| (a structure the prior excludes)
PRIOR_Z = 4.0


#: the coupling test (an exact randomisation p-value) refuses below this, Bonferroni over its layers
PRIOR_P = 0.01


#: Haar rotations drawn per layer by the coupling test (layers up to :data:`COUPLING_MC_WIDTH` outputs)
COUPLING_DRAWS = 20000


COUPLING_MC_WIDTH = 64


#: ... stopping early once this many exceed the observed statistic (Besag & Clifford 1991)
COUPLING_STOP = 20


def coupling_test(E: np.ndarray, W: np.ndarray, seed=0) -> tuple[float, float]:
    """Are the rows of the fitted offsets E coupled the way the rows of W are? ``(z, p)``.

    Under weight_error's prior the rows of E (one per output neuron) are independent draws of
    one law, whatever the programmed W: E's law is unchanged by any rotation O E of its rows
    (exactly for Gaussian rows N(0, V), any V). A coupling between the inputs, E = W M (dense
    crosstalk), gives rows whose Gram matrix E E^T follows W W^T. The statistic
    T = tr(A O M O^T), A = W W^T, M = E E^T, at O = I is referred to its law under Haar
    rotations O of the rows given E^T E -- an exact conditional test. In the eigenbases,
    T = sum_kj lam_k mu_j O_kj^2 over the r = rank(M) non-zero mu, so only r columns of each
    rotation are drawn (orthonormalised Gaussians): :data:`COUPLING_DRAWS` of them up to
    :data:`COUPLING_MC_WIDTH` rows (p with the +1 correction), stopped once
    :data:`COUPLING_STOP` exceed T (then p = that count over the draws: a valid sequential
    p-value, Besag & Clifford 1991, so a layer far from significance costs ~1000); beyond that a normal law with
    T's exact rotation mean tr(A) tr(M) / d and variance 2 tr(A~^2) tr(M~^2) / ((d - 1)(d + 2))
    (A~, M~ without their trace parts). One-sided: only a Gram aligned with W's is a coupling.
    ``seed``: the rotations' random numbers."""
    A, M = W @ W.T, E @ E.T
    d = A.shape[0]
    t0 = float(np.sum(A * M))
    if d <= COUPLING_MC_WIDTH:
        lam = np.linalg.eigvalsh(A)
        mu, _ = np.linalg.eigh(M)
        mu = mu[mu > 1e-12 * max(mu.max(), 1e-300)]
        rng = np.random.default_rng(seed)
        exceed, done = 0, 0
        while done < COUPLING_DRAWS:
            Q, _ = np.linalg.qr(rng.standard_normal((min(1000, COUPLING_DRAWS - done), d, mu.size)))
            t = np.einsum("k,bkj,j->b", lam, Q * Q, mu)
            exceed, done = exceed + int(np.sum(t >= t0 * (1 - 1e-12))), done + len(t)
            if exceed >= COUPLING_STOP:  # Besag & Clifford's sequential p-value: h / draws
                return float(stats.norm.isf(exceed / done)), float(exceed / done)
        p = (1 + exceed) / (1 + done)
        return float(stats.norm.isf(p)), float(p)
    At, Mt = A - np.trace(A) / d * np.eye(d), M - np.trace(M) / d * np.eye(d)
    mean = np.trace(A) * np.trace(M) / d
    sd = np.sqrt(2.0 * np.sum(At * At) * np.sum(Mt * Mt) / ((d - 1) * (d + 2)))
    z = float((t0 - mean) / sd) if sd > 0 else 0.0
    return z, float(stats.norm.sf(z))


def outlier_test(d: np.ndarray) -> tuple[int, float, float]:
    """Is one of the offsets ``d`` a gross outlier of N(0, e^2) draws, e unknown? Grubbs' test:
    G = max |d_i - mean| / sd, referred to its exact Student-t bound (P times the two-sided tail
    of t = sqrt(P (P - 2) G^2 / ((P - 1)^2 - P G^2)) on P - 2 degrees of freedom; exact for
    the largest value of P normal draws, conservative otherwise). ``(index, z, p)``."""
    d = np.ravel(np.asarray(d, np.float64))
    P = d.size
    sd = np.std(d, ddof=1) if P >= 3 else 0.0
    if P < 3 or sd <= 0:
        return 0, 0.0, 1.0
    i = int(np.argmax(np.abs(d - d.mean())))
    G = abs(d[i] - d.mean()) / sd
    den = (P - 1) ** 2 - P * G * G
    t = np.sqrt(P * (P - 2) * G * G / den) if den > 0 else np.inf
    p = float(min(1.0, P * 2.0 * stats.t.sf(t, P - 2))) if np.isfinite(t) else 0.0
    return i, float(stats.norm.isf(max(p / 2.0, 1e-300))) if p < 1.0 else 0.0, p


def refusing(rows) -> list[dict]:
    """The rows of :func:`prior_check` that refuse the fitted values: a normal-theory z beyond
    :data:`PRIOR_Z`, a coupling p below :data:`PRIOR_P` over the number of layers tested."""
    rows = list(rows or ())
    n_p = sum(1 for r in rows if "p" in r)
    return [r for r in rows if (r["p"] < PRIOR_P / n_p if "p" in r else abs(r["z"]) > PRIOR_Z)]


def prior_check(model: Model, meas: Measurement, seed: int = 0) -> list[dict]:
    """Do the fitted offsets look like their effect's prior -- E iid N(0, e^2) drawn
    independently of the programmed W (``weight_error``), delta iid N(0, sigma^2)
    (``bias_offset``)? Tests per layer, each a z (:func:`refusing` says which refuse):

    ``b_mean``         the mean of a layer's fitted bias offsets over their spread (Student t
                       on the normal scale): offsets all one way are a shifted transfer (an
                       activation's asymmetry seen through the biases), not draws of either sign;

    ``w_correlation``  atanh of the correlation of E_hat with W, times sqrt(P - 3): offsets
                       proportional to W are a gain (an activation slope seen through the
                       weights), not an error drawn apart from them;
    ``w_structure``    where the layer has more rows than columns (d_out >= d_in + 3), the F
                       test of E_hat = W M (each row of the error a fixed linear map of the row
                       of W: a coupling between the inputs, dense crosstalk): the share of
                       E_hat in the column space of W against d_in / d_out under the prior;
    ``w_coupling``     on every layer of two or more outputs, :func:`coupling_test`: the rows
                       of E_hat coupled as the rows of W are (a coupling W M on a layer of any
                       shape); its row also carries the exact p-value ``p``.

    ``{target}_outlier`` per layer and per-neuron family of five or more offsets (biases,
                       per-neuron parameters), :func:`outlier_test`: one
                       gross outlier (a 5-sigma offset among N(0, e^2) draws) is not a draw of
                       the prior; its row names the value (``neuron``, ``value``) and carries
                       the p-value ``p`` and a sentence ``what``.

    ``seed``: the coupling test's rotations (layer l draws with ``(seed, l)``).
    Returns one row per layer with offsets: ``{layer, test, z}`` for each test that applies.
    """
    all_kinds = kinds_of(list(model.offsets), meas.arch)
    deltas_of = offset_deltas(model, base_model(model, meas), meas, all_kinds)
    out = []
    for kind in (k for k in all_kinds if k.target == "b"):
        # bias_offset's prior is symmetric: offsets all one way are a shifted transfer, not a draw
        for l, d in zip(kind.layers, deltas_of[kind]):
            if d.size >= 3 and np.std(d, ddof=1) > 0:
                t = float(np.mean(d) / (np.std(d, ddof=1) / np.sqrt(d.size)))
                p = 2.0 * stats.t.sf(abs(t), df=d.size - 1)
                out.append({"layer": int(l), "test": "b_mean",
                            "z": float(np.sign(t) * stats.norm.isf(max(p / 2.0, 1e-300)))})
    # one gross outlier among the offsets (a dead or stuck neuron, a broken weight) is not a draw
    # of N(0, e^2): Grubbs' test per layer and family, the value named
    for kind in all_kinds:
        for l, d in zip(kind.layers, deltas_of[kind]):
            # per-neuron families only: a weight error's fitted entries are shrunk unevenly (most
            # directions set by the prior without taps), far from a sample of one normal law
            if kind.target == "W" or d.size < 5:
                continue
            i, z, p = outlier_test(d)
            where = f"{l}:{i}"
            out.append({"layer": int(l), "test": f"{kind.target}_outlier", "z": z, "p": p,
                        "neuron": where, "value": float(np.ravel(d)[i]),
                        "what": f"{kind.effect} offsets of layer {{l}} single out {where}: "
                                f"{float(np.ravel(d)[i]):+.3g} against the others' rms "
                                f"{float(np.sqrt(np.mean(np.delete(np.ravel(d), i) ** 2))):.3g} (not a draw of "
                                f"N(0, e^2): that one is unlike the rest, e.g. a dead or stuck neuron)"})
    kinds = [k for k in all_kinds if k.target == "W"]
    if not kinds:
        return out
    for l, E in zip(kinds[0].layers, deltas_of[kinds[0]]):
        W = np.asarray(meas.params[l - 1].W, np.float64)
        P = E.size
        if P > 3 and np.std(E) > 0 and np.std(W) > 0:
            rho = float(np.corrcoef(E.ravel(), W.ravel())[0, 1])
            out.append({"layer": int(l), "test": "w_correlation",
                        "z": float(np.arctanh(np.clip(rho, -0.999999, 0.999999)) * np.sqrt(P - 3))})
        d_out, d_in = W.shape
        if d_out >= d_in + 3 and np.linalg.matrix_rank(W) == d_in:
            proj = W @ np.linalg.pinv(W) @ E
            ss_p, ss_r = float(np.sum(proj ** 2)), float(np.sum((E - proj) ** 2))
            df1, df2 = d_in * d_in, (d_out - d_in) * d_in
            F = (ss_p / df1) / max(ss_r / df2, 1e-300)
            z = float(stats.norm.isf(max(stats.f.sf(F, df1, df2), 1e-300)))
            out.append({"layer": int(l), "test": "w_structure", "z": z})
        if d_out >= 2 and np.std(E) > 0:
            z, p = coupling_test(E, W, seed=(seed, int(l)))
            out.append({"layer": int(l), "test": "w_coupling", "z": z, "p": p})
    return out
