"""Stage 5c of the lab: how well the fit knows each parameter -- per-neuron standard errors and
95 % intervals on every fitted scalar parameter (reference §2b, §4).

Three kinds of fitted values, three methods, each honest for the way its value is fitted:

* **Per-neuron values** (a plugin's ``shape = {"p": "neurons"}``, the bias offsets of
  ``bias_offset``) are fitted as offsets with a Gaussian prior (:mod:`._offset_fit`). Their
  standard error is the posterior standard deviation of the linearised (Gauss-Newton) problem
  at the fit: ``cov = (J^T J / s2 + diag(1 / e^2))^-1`` with J the Jacobian of the fitted mean
  response in the offsets, s2 the residual mean square at the fit (so it includes the model's
  own sampling noise) and e the fitted prior scale. With taps J is block diagonal over the
  neurons of a layer (one small block per neuron, the fit's own draws); without taps it is the
  full Jacobian of the output means.
* **The scale of an offset family** (``bias_offset``'s sigma, ``weight_error``'s e, the spread
  of a per-neuron parameter) is the prior scale of per-device draws. Its interval is the
  profile-likelihood interval of the linearised *marginal* likelihood: the Gauss-Newton
  pseudo-data ``y = r + J d_hat`` is ``N(0, e^2 J J^T + s2 I)``, so in the singular basis of
  ``J / s`` its coordinates have variances ``e^2 d_k^2 + 1``; the interval is where twice the
  negative log-likelihood is within ``chi2_1(0.95) = 3.84`` of its minimum. It counts both the
  finite number of neurons (the device's draw) and each offset's measurement error.
* **Scalar parameters fitted by moments** (s, q, kappa, m, c, r, k, ... a plugin's scalars)
  minimise the simulated moment loss L(theta) (:mod:`._fit_moments`; theta on the log scale
  for a positive parameter). Their covariance is the sandwich (Godambe) form of an
  M-estimator, ``H^-1 V H^-1``: H the Hessian of L at the fit (central differences on the
  fit's common random numbers), V the covariance of grad L at the fit over B parametric
  replicates -- data simulated from the fitted model *and* fresh model draws, the two sources
  of the estimator's noise. The same replicates' mean gradient gives the estimator's bias seen
  from the fit, ``-H^-1 mean(grad L)`` (the log of a variance over r shots is biased by
  -1 / (r - 1)); the interval is ``theta_hat - bias +- t_{B-1} se sqrt(1 + 1 / B)`` mapped back
  to the parameter (asymmetric on the log scale) and clipped to the bounds.

The coverage of these intervals is measured by ``python -m studies.intervals`` (docs/lab.md).
"""

from __future__ import annotations

import math

import jax
import numpy as np
from scipy import optimize, stats

from .._measurement import Measurement
from .._model import named_subkey
from ..effects._base import is_per_neuron
from ._fit_moments import MomentProblem, _owner, _positive, _scalar, theta_of
from ._offset_fit import _joint_setup, _layer_jvps, _layer_setup, offset_deltas
from ._offset_kinds import base_model, fitted_as_offsets, kind_columns, kinds_of
from ._offset_null import _mean_output, _output_jacobian, resimulate
from ._shots import Model, params32, to32

#: the intervals' level
LEVEL = 0.95
#: parametric replicates of the moment fit's gradient (the sandwich's V)
REPLICATES = 30
#: central-difference step of the moment loss in theta (log scale: relative)
STEP = 0.02


# ---- per-neuron values and offset scales ------------------------------------------------------

def _blocks_taps(key, meas: Measurement, model: Model, kinds, base, deltas, scales):
    """Per layer and neuron with taps: the posterior standard errors of the per-neuron kinds and
    the marginal-likelihood pairs (d_k^2, c_k^2) of every kind (see the module docstring)."""
    arch = meas.arch
    p32 = params32(base.weights(meas))
    se = {k: [] for k in kinds}
    pairs = {k: ([], []) for k in kinds}
    for l in range(1, arch.depth + 1):
        here = tuple(k for k in kinds if l in k.layers)
        if not here:
            continue
        W, b = p32[l - 1]
        noise, a, t, target, _, axis = _layer_setup(jax.random.fold_in(named_subkey(key, "offsets"), l), meas,
                                                    base.physics, l)
        ds = tuple(np.asarray(deltas[k][k.layers.index(l)], np.float32) for k in here)
        basis, owner = kind_columns(here, arch, l)
        p0, cols = _layer_jvps(ds, W, b, a, noise, base.physics, t, basis, arch, l, axis, here)
        d_l = arch.widths[l]
        cols = np.asarray(cols, np.float64).reshape(len(owner), -1, d_l)  # (P_i, samples, neurons)
        r = np.asarray(target, np.float64).reshape(-1, d_l) - np.asarray(p0, np.float64).reshape(-1, d_l)
        s2 = np.maximum(np.mean(r * r, axis=0), 1e-30)  # residual mean square per neuron
        prior = np.array([1.0 / max(scales[here[o]], 1e-12) ** 2 for o in owner])
        dvec = [np.asarray(deltas[k][k.layers.index(l)], np.float64) for k in here]
        out_se = {k: np.zeros(d_l) for k in here}
        for i in range(d_l):
            J = cols[:, :, i].T  # (samples, P_i)
            cov = np.linalg.inv(J.T @ J / s2[i] + np.diag(prior))
            for ki, k in enumerate(here):
                idx = np.nonzero(owner == ki)[0]
                if k.target != "W":
                    out_se[k][i] = math.sqrt(max(cov[idx[0], idx[0]], 0.0))
                d_i = dvec[ki][i] if k.target != "W" else dvec[ki][i, :]
                Jk = J[:, idx] / math.sqrt(s2[i])
                y = r[:, i] / math.sqrt(s2[i]) + Jk @ np.atleast_1d(d_i)
                U, sv, _ = np.linalg.svd(Jk, full_matrices=False)
                pairs[k][0].append(sv ** 2)
                pairs[k][1].append((U.T @ y) ** 2)
        for k in here:
            se[k].append(out_se[k])
    se = {k: (None if k.target == "W" else v) for k, v in se.items()}
    return se, {k: (np.concatenate(d2), np.concatenate(c2)) for k, (d2, c2) in pairs.items()}


def _blocks_joint(key, meas: Measurement, model: Model, kinds, deltas, scales):
    """The same without taps, from the Jacobian of the output means in every offset at the fit."""
    arch, r = meas.arch, meas.r
    J, inv_v = _output_jacobian(key, meas, model, kinds)
    K, noise, t, targets, _ = _joint_setup(named_subkey(key, "jacobian"), meas, model.physics)
    pred = _mean_output(params32(model.weights(meas)), to32(meas.x), noise, model.physics, t, arch)
    res = np.asarray(targets[-1], np.float64).ravel() - np.asarray(pred, np.float64).ravel()
    v = inv_v / (1.0 + r / K)  # a measured mean's variance plus the model's K-draw mean's
    owner = np.concatenate([np.full(int(np.prod(k.shape(arch, l))), ki) for ki, k in enumerate(kinds) for l in k.layers])
    dflat = np.concatenate([np.ravel(np.asarray(d, np.float64)) for k in kinds for d in deltas[k]])
    prior = np.array([1.0 / max(scales[kinds[o]], 1e-12) ** 2 for o in owner])
    cov = np.linalg.inv(v * (J.T @ J) + np.diag(prior))
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    se, pairs, pos = {}, {}, 0
    for ki, k in enumerate(kinds):
        rows = []
        for l in k.layers:
            n_l = int(np.prod(k.shape(arch, l)))
            rows.append(sd[pos:pos + n_l].reshape(k.shape(arch, l)))
            pos += n_l
        se[k] = rows if k.target != "W" else None
        idx = np.nonzero(owner == ki)[0]
        Jk = math.sqrt(v) * J[:, idx]
        y = math.sqrt(v) * res + Jk @ dflat[idx]
        U, sv, _ = np.linalg.svd(Jk, full_matrices=False)
        pairs[k] = (sv ** 2, (U.T @ y) ** 2)
    return se, pairs


def scale_interval(d2, c2, level: float = LEVEL) -> tuple[float, float]:
    """Profile-likelihood interval of a prior scale e from pairs (d_k^2, c_k^2): coordinates of
    the whitened pseudo-data of variance ``e^2 d_k^2 + 1`` (module docstring). ``(lo, hi)``; lo
    is 0 when e = 0 is inside."""
    d2, c2 = np.asarray(d2, np.float64), np.asarray(c2, np.float64)
    keep = d2 > 1e-12 * max(float(np.max(d2, initial=0.0)), 1e-300)
    d2, c2 = d2[keep], c2[keep]
    if d2.size == 0:
        return 0.0, math.inf

    def nll(log_e):
        var = np.exp(2.0 * log_e) * d2 + 1.0
        return 0.5 * float(np.sum(np.log(var) + c2 / var))

    top = 0.5 * (np.log(float(np.sum(c2)) + 1.0) - np.log(float(np.min(d2))))
    res = optimize.minimize_scalar(nll, bounds=(top - 40.0, top + 2.0), method="bounded",
                                   options={"xatol": 1e-6})
    best, fbest = float(res.x), float(res.fun)
    cut = 0.5 * stats.chi2.ppf(level, 1)

    def g(u):
        return nll(u) - fbest - cut

    lo_end = top - 40.0
    lo = 0.0 if g(lo_end) <= 0 else math.exp(optimize.brentq(g, lo_end, best))
    hi_end = best + 1.0
    while g(hi_end) < 0 and hi_end < best + 50:
        hi_end += 1.0
    hi = math.exp(optimize.brentq(g, best, hi_end)) if g(hi_end) > 0 else math.inf
    return lo, hi


def offset_uncertainty(key, meas: Measurement, model: Model, weights: bool = True) -> dict:
    """Per-neuron standard errors and the scale intervals of ``model``'s offset families.

    Parameters
    ----------
    key : the PRNG key the offsets were fitted with (:func:`~gift_theory.lab.fit_model`'s), so
        the Jacobian is the fit's own
    meas : the measurement they were fitted to
    model : a fitted model with offsets (``model.offsets``)
    weights : include the weight offsets (``weight_error``: d_in columns per neuron; without
        taps the full Jacobian of every weight); False leaves them at their fit

    Returns
    -------
    {"se": {kind: [array (d_l,) per layer in scope] or None for weight offsets},
     "intervals": {effect name: (lo, hi)}, "offsets": {bias kind: [fitted offsets (d_l,) per layer]}}
    """
    names = [n for n in model.offsets if fitted_as_offsets(n)]
    kinds = tuple(k for k in kinds_of(names, meas.arch) if weights or k.target != "W")
    if not kinds:
        return {"se": {}, "intervals": {}, "offsets": {}}
    base = base_model(model, meas)
    deltas = offset_deltas(model, base, meas, kinds)
    scales = {k: float(model.offsets.get(k.effect, 0.0)) or 1e-3 for k in kinds}
    if meas.has_taps:
        se, pairs = _blocks_taps(key, meas, model, kinds, base, deltas, scales)
    else:
        se, pairs = _blocks_joint(key, meas, model, kinds, deltas, scales)
    intervals = {}
    for k in kinds:
        if k.effect not in intervals:  # one scale per effect (its first kind)
            intervals[k.effect] = scale_interval(*pairs[k])
    return {"se": se, "intervals": intervals, "offsets": {k: deltas[k] for k in kinds if k.target == "b"}}


def attach_uncertainty(model: Model, info: dict) -> Model:
    """Keep :func:`offset_uncertainty`'s answer with the fitted model (read by :func:`per_neuron_json`)."""
    object.__setattr__(model, "_uncertainty", info)
    return model


def uncertainty_of(model: Model) -> dict | None:
    return getattr(model, "_uncertainty", None)


def per_neuron_json(model: Model, arch=None) -> dict:
    """``{"per_neuron": {name: {"<layer>": [value per neuron]}}, "per_neuron_se": {same shape}}``
    (reference §2b) of a fitted model: every per-neuron parameter by its name on the layers in
    its scope, and ``bias_offset``'s fitted offsets under ``"bias_offset"``. A standard error
    not known is null."""
    info = uncertainty_of(model) or {"se": {}}
    by_kind = {(k.effect, k.target): (k, rows) for k, rows in info["se"].items()}
    values, ses = {}, {}
    for e in model.physics.effects:
        for p, kind in e.shape.items():
            if kind != "neurons":
                continue
            v = getattr(e, p)
            layers = [l for l in range(1, len(v) + 1)] if is_per_neuron(v) else []
            found = by_kind.get((e.name, p))
            vals, sds = {}, {}
            for l in layers:
                if arch is not None and not e.acts_on(l, arch.depth):
                    continue
                row = np.ravel(np.asarray(v[l - 1], np.float64))
                if row.size == 0 or (found is not None and l not in found[0].layers):
                    continue
                vals[str(l)] = [float(x) for x in row]
                if found is not None and found[1] is not None:
                    sds[str(l)] = [float(x) for x in found[1][found[0].layers.index(l)]]
                else:
                    sds[str(l)] = [None] * row.size
            if vals:
                values[p], ses[p] = vals, sds
    for k, deltas in info.get("offsets", {}).items():
        if k.target != "b":
            continue
        rows = info["se"].get(k)
        values[k.effect] = {str(l): [float(x) for x in d] for l, d in zip(k.layers, deltas)}
        ses[k.effect] = {str(l): ([float(x) for x in rows[i]] if rows is not None else [None] * len(d))
                         for i, (l, d) in enumerate(zip(k.layers, deltas))}
    return {"per_neuron": values, "per_neuron_se": ses}


# ---- scalar parameters fitted by moments -------------------------------------------------------

def free_scalars(physics, meas: Measurement) -> tuple:
    """The parameters :func:`~gift_theory.lab._fit_moments.fit_moments` fits (scalar, not read
    off the data)."""
    from . import _fit_moments as fm

    fixed = set()
    for e in physics.effects:
        fixed |= set((type(e).from_data(meas.layers()) or {}).keys())
    shaped = {p for e in physics.effects for p in e.shape}
    free = tuple(p for p, v in physics.params().items() if p not in fixed and p not in shaped and _scalar(v))
    coords = getattr(fm, "per_layer_coordinates", None)  # per-layer parameters: one coordinate "p@l" per layer
    if coords is not None:
        free += tuple(c for c in coords(physics, meas.arch) if c.partition("@")[0] not in fixed)
    return free


def _per_layer_form(physics, arch):
    from . import _fit_moments as fm

    conv = getattr(fm, "per_layer_arrays", None)
    return physics if conv is None else conv(physics, arch)


def _grad(f, theta, h=STEP):
    g = np.zeros(len(theta))
    for i in range(len(theta)):
        e = np.zeros(len(theta))
        e[i] = h
        g[i] = (float(f(theta + e)) - float(f(theta - e))) / (2.0 * h)
    return g


def _hessian(f, theta, h=STEP):
    """Central second differences (symmetric)."""
    p = len(theta)
    H = np.zeros((p, p))
    f0 = float(f(theta))
    for i in range(p):
        ei = np.zeros(p)
        ei[i] = h
        H[i, i] = (float(f(theta + ei)) - 2.0 * f0 + float(f(theta - ei))) / h ** 2
        for j in range(i):
            ej = np.zeros(p)
            ej[j] = h
            H[i, j] = H[j, i] = (float(f(theta + ei + ej)) - float(f(theta + ei - ej)) - float(f(theta - ei + ej))
                                 + float(f(theta - ei - ej))) / (4.0 * h * h)
    return H


def moment_intervals(key, meas: Measurement, model: Model, K: int | None = None, *, B: int = REPLICATES,
                     level: float = LEVEL, problem: MomentProblem | None = None, progress=None) -> dict:
    """Sandwich intervals of the scalar parameters a moment fit of ``model`` to ``meas`` found.

    Parameters
    ----------
    key : PRNG key of the fit (its moment problem's draws: ``MomentProblem(key, meas, K)``)
    meas : the measurement the model was fitted to
    model : the fitted model
    K : model shots per input of the moment fit (default 2 r, as the fit)
    B : parametric replicates of the loss gradient
    problem : the fit's :class:`MomentProblem` when already made
    progress : None or ``f(done, total)``

    Returns
    -------
    {"intervals": {param: (lo, hi)}, "se_theta": {param: float}, "bias_theta": {param: float},
     "theta_scale": {param: "log"|"linear"}, "replicates": B, "joint": {"params", "scale", "centre",
     "estimate", "cov", "level", "dof"}}: a per-layer parameter's coordinates are named ``"p@l"``
     (layer l, 1-based); ``joint`` is the sandwich's covariance of every free parameter on its
     fit scale (log for a positive one), around the bias-corrected centre (the pair plot's
     joint region)
    """
    physics = _per_layer_form(model.physics, meas.arch)
    free = free_scalars(physics, meas)
    if not free:
        return {"intervals": {}, "se_theta": {}, "theta_scale": {}, "replicates": 0}
    problem = problem or MomentProblem(key, meas, K)
    params = model.weights(meas)
    theta = theta_of(physics, free)
    f = problem.loss(physics, params, free)
    H = _hessian(f, theta)
    grads = []
    k_rep = named_subkey(key, "interval_replicates")
    for b in range(B):
        kb = jax.random.fold_in(k_rep, b)
        sim = resimulate(named_subkey(kb, "data"), model, meas)
        fb = MomentProblem(named_subkey(kb, "draws"), sim, problem.K).loss(physics, params, free)
        grads.append(_grad(fb, theta))
        if progress is not None:
            progress(b + 1, B)
    G = np.array(grads)
    V = np.cov(G, rowvar=False).reshape(len(free), len(free))
    try:
        Hinv = np.linalg.pinv(0.5 * (H + H.T))
    except np.linalg.LinAlgError:  # pragma: no cover - pinv of a finite matrix converges
        Hinv = np.full_like(H, np.nan)
    # the replicates' mean gradient at theta_hat is the estimator's bias seen from theta_hat:
    # theta* - theta_hat ~ -H^-1 grad L(theta_hat; D*), so the fit is biased by -H^-1 mean(G)
    # (measured: s came out low by 0.6-0.9 standard errors -- the log of a variance over r
    # shots is biased by -1 / (r - 1), the model's over K shots by less); the interval is
    # centred on theta_hat minus that bias, its variance grown by the bias estimate's (1 / B)
    bias = -Hinv @ G.mean(axis=0)
    cov = Hinv @ V @ Hinv * (1.0 + 1.0 / B)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    q = stats.t.ppf(0.5 + level / 2.0, df=max(B - 1, 1))
    out, scale = {}, {}
    centre = theta - bias
    for i, p in enumerate(free):
        lo_th, hi_th = centre[i] - q * se[i], centre[i] + q * se[i]
        pos = _positive(physics, p)
        lo, hi = (math.exp(min(lo_th, 700.0)), math.exp(min(hi_th, 700.0))) if pos else (lo_th, hi_th)
        blo, bhi = type(_owner(physics, p)).bounds.get(p.partition("@")[0], (-math.inf, math.inf))
        if not np.isfinite(se[i]) or H[i, i] <= 0:
            lo, hi = blo, bhi  # a loss flat or concave here: the data do not pin the parameter
        out[p] = (max(lo, blo), min(hi, bhi))
        scale[p] = "log" if pos else "linear"
    return {"intervals": out, "se_theta": dict(zip(free, se.tolist())), "bias_theta": dict(zip(free, bias.tolist())),
            "theta_scale": scale, "replicates": B,
            "joint": {"params": list(free), "scale": [scale[p] for p in free], "centre": centre.tolist(),
                      "estimate": [float(math.exp(t)) if scale[p] == "log" else float(t) for p, t in zip(free, theta)],
                      "cov": cov.tolist(), "level": level, "dof": max(B - 1, 1)}}
