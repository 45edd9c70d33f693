"""Stage 5a of the lab: scalar physical parameters by simulated moment matching.

The model's shots for the fitting inputs are a deterministic function of the physics
parameters once the standard draws are fixed (the core's explicit-noise forward pass), so
the per-cell moments of the model -- mean and log variance per neuron, log variance of the
layer sum (cross-neuron correlation: common mode), slope against acquisition time (drift)
-- are smooth in the parameters except through rounding (quantization). The loss is the sum
of the standardised squared moment differences over every measured cell (taps and output).
It is minimised by a one-dimensional scan over each new parameter -- the values come from
the effect itself (:meth:`gift_theory.effects.Effect.search`: its bounds and defaults, or a
scale read off the data) -- followed by a local search on all of them (Brent's method for
one, Nelder-Mead for several; no gradient needed: a reverse-mode gradient of the loss costs
~6 evaluations).

A per-layer parameter (``shape = {"g": "layers"}``: ``layer_gain``'s g) is one coordinate
per layer in its effect's scope, named ``"g@l"`` (l 1-based), each scanned in layer order (a
layer's gain moves its own tap's moments first) over the effect's ``search`` values.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize

from .._finite import NotFinite, check_finite
from .._measurement import Measurement
from .._model import named_subkey
from ._qtest import log_variance_bias
from ._shots import draws, eager_forward_at, layer_outputs, params32, strong32, tiled_times, to32


def _moments(A, t):
    """Per-cell moments of shots A (n, K, d) with times t (n, K) or None."""
    K = A.shape[1]
    m = jnp.mean(A, 1)
    v = jnp.var(A, 1) * K / (K - 1)
    sv = jnp.var(jnp.sum(A, -1), 1) * K / (K - 1)
    out = {"m": m, "v": v, "sv": sv}
    if t is not None:
        tc = t - jnp.mean(t, 1, keepdims=True)
        vt = jnp.mean(tc ** 2, 1)
        out["beta"] = jnp.einsum("nk,nkd->nd", tc, A - m[:, None, :]) / K / jnp.maximum(vt, 1e-12)[:, None]
        out["vt"] = vt
    return out


#: the data's moments in one program per layer shape (dispatched op by op they were ~30
#: programs of a diagnosis, each traced and lowered in a fresh process)
_moments_jit = jax.jit(_moments)


def _moment_loss(mod, dat, r, K):
    """Mean standardised squared difference of the moments (one layer).

    The log variances are compared net of their own bias (:func:`log_variance_bias`): the data
    have r - 1 degrees of freedom, the model's shots K - 1, so log v of the data sits lower by
    about 1 / (r - 1) - 1 / (K - 1) -- matched uncorrected, the fitted noise variance came out
    that much too small (s 1.6-2.2 % low at r = 16, K = 32, measured), which a wide layer's
    test then rejects on the true model."""
    vfloor = 1e-6 * jnp.mean(dat["v"]) + 1e-20
    shift = log_variance_bias(r - 1) - log_variance_bias(K - 1)
    lv = jnp.log(mod["v"] + vfloor) - jnp.log(dat["v"] + vfloor) + shift
    lsv = jnp.log(mod["sv"] + vfloor) - jnp.log(dat["sv"] + vfloor) + shift
    var_lv = 2.0 / (r - 1) + 2.0 / (K - 1)
    terms = [jnp.mean((mod["m"] - dat["m"]) ** 2 / (dat["v"] / r + mod["v"] / K + vfloor)),
             jnp.mean(lv ** 2) / var_lv, jnp.mean(lsv ** 2) / var_lv]
    if "beta" in dat:
        vt = jnp.maximum(dat["vt"], 1e-12)[:, None]
        se2 = (dat["v"] / r + mod["v"] / K) / vt + vfloor
        # cells whose shots span no time carry no slope information
        w = (dat["vt"] > 1e-10)[:, None]
        terms.append(jnp.sum(w * (mod["beta"] - dat["beta"]) ** 2 / se2) / jnp.maximum(jnp.sum(w) * dat["m"].shape[1], 1))
    return sum(terms)


@functools.partial(jax.jit, static_argnames=("rK",))
def _loss_of_outputs(outs, dat, t, rK):
    r, K = rK
    total = 0.0
    for A, d in zip(outs, dat):
        if d is not None:
            total = total + _moment_loss(_moments(A, t), d, r, K)
    return total


@jax.jit
def _theta_values(theta, positive):
    """The free parameters' values at ``theta`` (float32): exp where fitted on the log scale."""
    return jnp.where(positive, jnp.exp(theta), theta)


_MOMENT_NAMES = {"m": "mean", "v": "variance", "sv": "variance of the layer sum", "beta": "slope in time",
                 "vt": "variance of the times"}


class MomentProblem:
    """The fitting data of one measurement (its per-cell moments), shared by every candidate."""

    def __init__(self, key, meas: Measurement, K: int | None = None):
        self.meas = meas
        self.key = named_subkey(key, "moments")
        self.K = 2 * meas.r if K is None else int(K)
        self.x = to32(meas.x)
        self.t = tiled_times(meas, self.K)
        t = None if meas.t is None else to32(meas.t)
        dat = tuple(_moments_jit(to32(Y), t) for Y in meas.layers())
        ids = meas.layer_ids()
        for l, d in zip(ids, dat):  # the data's own moments in float32: an overflow here is no fit
            for name, v in d.items():
                check_finite(v, f"the measured shots' {_MOMENT_NAMES.get(name, name)} of layer {l} (float32; values up "
                                f"to {float(np.max(np.abs(meas.layers()[ids.index(l)]))):.3g})")
        # forward returns every layer; only measured ones enter the loss
        self.dat = tuple(dat[ids.index(l)] if l in ids else None for l in range(1, meas.arch.depth + 1))

    def probe(self, physics, params) -> None:
        """The model's shots of the fitting inputs, run eagerly: a plugin hook whose result is not
        finite (or breaks its contract) raises its own one-line GiftInputError here."""
        noise = draws(self.key, physics, self.meas, self.K)
        eager_forward_at(params32(params), self.x, noise, strong32(physics), self.meas.arch, self.t)

    def loss(self, physics, params, free):
        """``theta -> moment loss`` for the free parameters (common random numbers: one set of
        draws for every theta)."""
        noise = draws(self.key, physics, self.meas, self.K)
        p32 = params32(params)
        r, K, t, arch = self.meas.r, self.K, self.t, self.meas.arch
        positive = np.array([_positive(physics, p) for p in free], bool)

        def f(theta):
            vals = np.asarray(_theta_values(np.asarray(theta, np.float32), positive))
            phys = strong32(with_values(physics, {p: vals[i] for i, p in enumerate(free)}))
            # the comparison's program (model_shots: same physics structure, shapes and leaf
            # types), so a candidate's forward compiles once for its fit and its shots; the
            # moments and the loss are one program for every candidate
            outs = layer_outputs(p32, self.x, noise, phys, arch, t)
            return _loss_of_outputs(outs, self.dat, t, (r, K))
        return f


def _scalar(v) -> bool:
    """A scalar parameter (per-neuron values are fitted as offsets, not by moments)."""
    return not isinstance(v, (tuple, list)) and np.ndim(v) == 0


def _split(p: str) -> tuple[str, int | None]:
    """``"g@2"`` -> ``("g", 2)`` (a per-layer coordinate), ``"s"`` -> ``("s", None)``."""
    name, at, layer = p.partition("@")
    return (name, int(layer)) if at else (name, None)


def _owner(physics, p):
    name = _split(p)[0]
    return next(e for e in physics.effects if name in e.params)


def per_layer_coordinates(physics, arch) -> tuple[str, ...]:
    """The coordinates ``"p@l"`` of every per-layer parameter of ``physics`` on the layers of
    its effect's scope (l 1-based)."""
    return tuple(f"{p}@{l}" for e in physics.effects for p, kind in e.shape.items() if kind == "layers"
                 for l in range(1, arch.depth + 1) if e.acts_on(l, arch.depth))


def per_layer_arrays(physics, arch):
    """``physics`` with every per-layer parameter held as one (1,)-array per layer (a scalar
    value repeated), the form :func:`with_values` sets coordinates of."""
    todo = {p: getattr(e, p) for e in physics.effects for p, kind in e.shape.items() if kind == "layers"
            and _scalar(getattr(e, p))}
    if not todo:
        return physics
    return physics.replace(**{p: tuple(np.full((1,), float(v)) for _ in range(arch.depth)) for p, v in todo.items()})


def with_values(physics, vals: dict):
    """``physics.replace`` of scalar parameters and per-layer coordinates ``"p@l"`` (traceable:
    the values may be JAX tracers; a per-layer parameter must already be held per layer)."""
    plain = {p: v for p, v in vals.items() if _split(p)[1] is None}
    rows: dict = {}
    for p, v in vals.items():
        name, l = _split(p)
        if l is not None:
            if name not in rows:
                rows[name] = list(_owner(physics, name).param_dict()[name])
            if isinstance(v, jax.core.Tracer):
                rows[name][l - 1] = jnp.reshape(v, (1,))
            else:  # on the host, as jnp.reshape would hold it (float32 unless x64), no dispatch
                v = np.asarray(v)
                rows[name][l - 1] = np.reshape(v.astype(jax.dtypes.canonicalize_dtype(v.dtype)), (1,))
    return physics.replace(**plain, **{k: tuple(v) for k, v in rows.items()}) if plain or rows else physics


def _current(physics, p) -> float:
    """The value of a scalar parameter or of one per-layer coordinate."""
    name, l = _split(p)
    v = _owner(physics, p).param_dict()[name]
    return float(np.asarray(v if l is None else v[l - 1]).reshape(-1)[0])


def _positive(physics, p) -> bool:
    """A parameter with a lower bound >= 0 is fitted on the log scale."""
    return type(_owner(physics, p)).bounds.get(_split(p)[0], (-np.inf, np.inf))[0] >= 0


def theta_of(physics, free):
    return np.array([np.log(max(_current(physics, p), 1e-12)) if _positive(physics, p) else _current(physics, p)
                     for p in free])


def values_of(physics, free, theta) -> dict:
    return {p: float(np.exp(th) if _positive(physics, p) else th) for p, th in zip(free, theta)}


def _simplex(theta, step=0.25):
    pts = [theta.copy()]
    for i in range(len(theta)):
        p = theta.copy()
        p[i] += step if abs(theta[i]) < 1 else step * abs(theta[i])
        pts.append(p)
    return np.array(pts)


#: the local search's resolution in theta (log scale: relative) and in the loss
XATOL, FATOL = 1e-3, 1e-4


def _brent(f, theta):
    """One coordinate by Brent's method from ``theta`` (1-vector), to ``XATOL`` in theta; None
    when no bracket of a minimum is found (a loss still falling at the bracket's limit)."""
    t0 = float(theta[0])
    try:
        # a loss still falling far out sends scipy's bracket search to overflow: that is its
        # "no minimum in reach", answered by the non-finite value below, not a warning
        with np.errstate(over="ignore", invalid="ignore"):
            res = optimize.minimize_scalar(lambda v: float(f(np.array([v]))), bracket=(t0 - 0.25, t0),
                                           method="brent", options={"xtol": XATOL / max(abs(t0), XATOL), "maxiter": 200})
    except (RuntimeError, ValueError):  # scipy's BracketError: no minimum in reach
        return None
    if not np.isfinite(res.fun):
        return None
    return np.array([float(res.x)]), float(res.fun)


def optimise(f, theta0, grids):
    """Scan each coordinate listed in ``grids`` (index -> theta values), then a local search on
    all: Brent's method for a single coordinate (~8 evaluations where Nelder-Mead takes 22-31,
    to its loss within 1.3e-4 on the six such fits of a diagnose), Nelder-Mead for several."""
    theta = np.array(theta0, dtype=np.float64)
    f0 = None  # f(theta), once a scan has evaluated it (f is deterministic)
    for i, values in grids.items():
        best, bv = None, np.inf
        for v in values:
            th = theta.copy()
            th[i] = v
            val = float(f(th))
            if np.isfinite(val) and val < bv:
                best, bv = v, val
        if best is not None:
            theta[i], f0 = best, bv
    found = _brent(f, theta) if len(theta) == 1 else None
    if found is None:
        res = optimize.minimize(lambda th: float(f(th)), theta, method="Nelder-Mead",
                                options={"xatol": XATOL, "fatol": FATOL, "maxiter": 80 * len(theta),
                                         "initial_simplex": _simplex(theta)})
        found = res.x, float(res.fun)
    f0 = float(f(theta)) if f0 is None else f0
    return found if found[1] <= f0 else (theta, f0)


def fit_moments(problem: MomentProblem, physics, params, scan, rescan_s: bool = False):
    """Fit every free scalar parameter of ``physics`` (those no effect reads off the data).

    scan : names of the parameters to scan first (the new ones), each over its effect's
        :meth:`~gift_theory.effects.Effect.search` values (a per-layer parameter: each of its
        coordinates, in layer order)
    rescan_s : scan awgn's s down from its value once more after the new parameters: an added
        effect usually takes over part of the variance s had absorbed

    Returns
    -------
    physics with fitted values
    """
    fixed = set()
    for e in physics.effects:
        fixed |= set((type(e).from_data(problem.meas.layers()) or {}).keys())
    arch = problem.meas.arch
    physics = per_layer_arrays(physics, arch)
    shaped = {p for e in physics.effects for p in e.shape}
    free = tuple(p for p, v in physics.params().items() if p not in fixed and p not in shaped and _scalar(v))
    free += tuple(c for c in per_layer_coordinates(physics, arch) if _split(c)[0] not in fixed)
    if not free:
        return physics
    f = problem.loss(physics, params, free)
    theta0 = theta_of(physics, free)
    layers = problem.meas.layers()
    grids = {}
    for p in scan:
        for c in (c for c in free if _split(c)[0] == p):
            vals = np.asarray(type(_owner(physics, c)).search(p, layers), np.float64)
            grids[free.index(c)] = np.log(vals) if _positive(physics, c) else vals
    if rescan_s and "s" in free:
        i = free.index("s")
        grids.pop(i, None)
        grids[i] = np.log(max(float(physics.s), 1e-12)) + np.log([0.4, 0.55, 0.7, 0.85, 1.0, 1.1])
    theta, loss = optimise(f, theta0, grids)
    if not np.isfinite(loss):  # every value tried gave a non-finite loss: nothing was fitted
        problem.probe(physics, params)  # a plugin hook behind it is named there (a bad input)
        raise NotFinite(f"the moment fit of {', '.join(free)} ({physics.describe()}): its loss is not finite at any "
                        f"value tried (the model's or the data's moments overflow float32)")
    return with_values(physics, {p: np.float64(v) for p, v in values_of(physics, free, theta).items()})
