"""Per-input Monte-Carlo samples of J_s, grad J_s and its s-derivatives for small ONNs.

Each input k carries its own K2 standard noise draws; the per-input average over those
draws is one independent unit, so an estimate is the mean over K1 units with its
standard error (lem:Hierarchical-sampling-is-unbiased). Derivatives in s are pathwise
(autodiff through ``s * xi`` with the standard draws xi held fixed), so the same draws
at two noise levels give common random numbers. The printed estimator D^[0]
(eqs. sample_D0_Wi / sample_D0_bi) comes from :mod:`gift_theory.estimators`
(``method="score_paper"``).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

import gift_theory as gt

_WHAT = ("loss", "grad", "ds", "ds2", "hvp")


@partial(jax.jit, static_argnames=("arch", "what"))
def _per_input(params, s, x, y, noise, physics, arch, what, vec=None):
    def loss(p, s_, x1, y1, n1):
        out = gt.forward(p, x1[None, :], n1, physics.replace(s=s_), arch).y
        return jnp.mean(jnp.sum((y1 - out) ** 2, axis=-1))

    g = jax.grad(loss)

    def flat(f):
        return lambda *a: ravel_pytree(f(*a))[0]

    if what == "loss":
        fn = loss
    elif what == "grad":
        fn = flat(g)
    elif what == "ds":
        fn = flat(jax.jacfwd(g, argnums=1))
    elif what == "ds2":
        fn = flat(jax.jacfwd(jax.jacfwd(g, argnums=1), argnums=1))
    elif what == "hvp":
        _, unravel = ravel_pytree(params)
        tangent = unravel(vec)
        fn = flat(lambda p, s_, x1, y1, n1: jax.jvp(lambda q: g(q, s_, x1, y1, n1), (p,), (tangent,))[1])
    else:
        raise ValueError(what)
    return jax.vmap(fn, in_axes=(None, None, 0, 0, 0))(params, s, x, y, noise)


def per_input(what: str, params, s, x, y, noise, physics, arch, vec=None) -> np.ndarray:
    """Per-input samples of ``what`` in {"loss", "grad", "ds", "ds2", "hvp"}.

    Parameters
    ----------
    params : tuple of gt.Layer
    s : noise level at which to evaluate (the physics' other parameters are kept)
    x : (K1, d_0), y : (K1, d_L)
    noise : dict of standard draws with leaves (K1, K2, d)
    vec : (P,) flat direction, for ``what="hvp"`` (Hessian of J_s times vec)

    Returns
    -------
    ndarray (K1,) for "loss", else (K1, P) with P the number of parameters (flattened
    in the order of ``jax.flatten_util.ravel_pytree(params)``).
    """
    dtype = params[0].W.dtype
    s = jnp.asarray(s, dtype)
    vec = None if vec is None else jnp.asarray(vec, dtype)
    return np.asarray(_per_input(params, s, jnp.asarray(x, dtype), jnp.asarray(y, dtype), noise, physics, arch,
                                 what, vec), dtype=np.float64)


def draws(key, arch, physics, K1, K2, dtype=jnp.float64) -> dict:
    """Standard draws with leaves (K1, K2, d) (same key, same draws)."""
    return gt.sample_noise(key, arch, physics, (K1, K2), dtype)


def estimate(samples) -> gt.Estimate:
    """Mean and standard error over the K1 independent per-input units."""
    return gt.estimate_from_samples(samples)


def d0_printed(key, params, x, y, physics, arch, K2) -> gt.Estimate:
    """The printed D^[0](K1, K2) (eqs. sample_D0_Wi / sample_D0_bi) as a flat vector with its
    standard error, from the shared ``gift_theory.estimators.d_ds_grad(method="score_paper")``."""
    from gift_theory.estimators import d_ds_grad

    est = d_ds_grad(key, params, x, y, physics, arch, method="score_paper", K2=K2)
    mean = np.asarray(ravel_pytree(est.mean)[0], dtype=np.float64)
    se = np.asarray(ravel_pytree(est.se)[0], dtype=np.float64)
    return gt.Estimate(mean, se, est.n)


class Problem(NamedTuple):
    """A small ONN learning task: data (the empirical measure mu), architecture, physics."""

    x: np.ndarray
    y: np.ndarray
    arch: gt.Architecture
    physics: gt.Physics


def teacher_problem(key, arch: gt.Architecture, n: int = 256, s: float = 0.1) -> Problem:
    """Inputs uniform in [0, 1]^{d_0}, targets from a random noiseless tanh teacher of ``arch``.

    The data distribution mu is the empirical measure of these n points, so J_s is an
    expectation over the noise only and K1 = n covers mu exactly.
    """
    kx, kt = jax.random.split(key)
    x = jax.random.uniform(kx, (n, arch.widths[0]), jnp.float64)
    teacher = gt.init_params(kt, arch, dtype=jnp.float64, gain=2.0)
    y = gt.forward(teacher, x, {}, gt.Physics.create(s=None), arch).y
    return Problem(np.asarray(x), np.asarray(y), arch, gt.awgn(s))


def train_critical(key, problem: Problem, s: float, *, K2: int = 32, steps: int = 1500, lr: float = 0.05,
                   init=None, box: gt.Box | None = None):
    """An approximate critical point of J_s: full-batch Adam on n x K2 fixed draws, then
    plain gradient steps. Returns params (float64). Used to build w0 for the checks."""
    import optax

    arch = problem.arch
    params = init if init is not None else gt.init_params(jax.random.fold_in(key, 1), arch, dtype=jnp.float64)
    noise = draws(jax.random.fold_in(key, 2), arch, problem.physics, problem.x.shape[0], K2)
    x = jnp.asarray(problem.x)[:, None, :]
    y = jnp.asarray(problem.y)[:, None, :]
    phys = problem.physics.replace(s=s)

    def J(p):
        return jnp.mean(jnp.sum((y - gt.forward(p, x, noise, phys, arch).y) ** 2, axis=-1))

    opt = optax.adam(lr)

    @jax.jit
    def run(p):
        def step(c, i):
            p, st = c
            g = jax.grad(J)(p)
            u, st = opt.update(g, st, p)
            p = optax.apply_updates(p, u)
            if box is not None:
                p = gt.project(p, box)
            return (p, st), None
        (p, _), _ = jax.lax.scan(step, (p, opt.init(p)), jnp.arange(steps))
        return p

    return run(params)


def paired_difference_on_mu(key, params_a, params_b, x, y, physics, arch, K2: int,
                            chunk: int = 4096) -> gt.Estimate:
    """J_s(w_a) - J_s(w_b) when mu is the empirical measure of the given points (all used):
    only the noise is random, so the standard error comes from the noise alone. The K2 draws per
    input are split into two independent halves (common random numbers between w_a and w_b within
    each); with per-input half differences d_i^A, d_i^B, Var(mean) = sum_i E(d_i^A - d_i^B)^2 / (4 n^2).
    """
    kA, kB = jax.random.split(key)
    h = max(K2 // 2, 1)
    dA, dB = (gt.paired_difference(k, params_a, params_b, x, y, physics, arch, K2=h, chunk=chunk).samples
              for k in (kA, kB))
    n = dA.shape[0]
    mean = float(0.5 * (dA.mean() + dB.mean()))
    se = float(np.sqrt(np.sum((dA - dB) ** 2)) / (2 * n))
    return gt.Estimate(mean, se, n, 0.5 * (dA + dB))


def trivial_critical_point(arch: gt.Architecture, y, dtype=jnp.float64):
    """W_l = 0, b_l = 0 (l < L), b_L = mean of y: a critical point of J_s for every s (tanh):
    R^(l) = 0 below the last layer, and E[R^(L)] = E[y] - b_L = 0, E[R^(L) A^(L-1)^T] = 0
    because A^(L-1) is then noise independent of y and of N^w,(L)."""
    layers = []
    for l in range(1, arch.depth + 1):
        W = jnp.zeros((arch.widths[l], arch.widths[l - 1]), dtype)
        b = jnp.asarray(np.mean(y, axis=0), dtype) if l == arch.depth else jnp.zeros((arch.widths[l],), dtype)
        layers.append(gt.Layer(W, b))
    return tuple(layers)


def symmetric_draws(key, arch: gt.Architecture, physics, K1: int, K2: int, dtype=jnp.float64) -> dict:
    """Standard draws with leaves (K1, K2, d) in sign-symmetric groups of four: K2 / 4 base draws,
    each repeated with the sites of the last hidden layer (w{L-1} and a{L-1}) negated together and
    with the output site wL negated (the other sites unchanged). The finite-mean objective over
    these draws keeps the symmetry the Gaussian law gives the trivial point (W = 0, hidden b = 0,
    b_L = mean y): there its gradient vanishes exactly (:func:`trivial_point_certificate`)."""
    if K2 % 4:
        raise ValueError("K2 must be a multiple of 4 (sign-symmetric groups of four)")
    base = gt.sample_noise(key, arch, physics, (K1, K2 // 4), dtype)
    L = arch.depth
    group_a, group_b = {f"w{L - 1}", f"a{L - 1}"}, {f"w{L}"}
    signs = ((1, 1), (-1, 1), (1, -1), (-1, -1))
    out = {}
    for name, d in base.items():
        parts = [d * (sa if name in group_a else 1) * (sb if name in group_b else 1) for sa, sb in signs]
        out[name] = jnp.stack(parts, axis=2).reshape(K1, K2, *d.shape[2:])
    return out


def trivial_point_certificate(arch: gt.Architecture, draws: dict, y, unravel):
    """A ``certify(w_flat, s)`` hook for :func:`proofs_checks.family` (the Theorem-1 checker calls it
    where Krawczyk's test cannot succeed): proves that the finite-mean objective
    J_s(w) = mean_{k, m} ||y_k - M_s(x_k, w, N_{k,m})||^2 over the sign-symmetric ``draws``
    (:func:`symmetric_draws`) has an exact critical point within rounding of the trivial point
    w = (W_l = 0, b_l = 0 for l < L, b_L = mean y), for every s. Computed, not assumed:

    * the point's W_l and hidden b_l are exactly 0.0 and the draws come in exact sign groups
      (array equality, bit for bit);
    * sympy: at such a point the per-draw gradient of the loss (tanh activation) summed over one
      sign group is exactly (0, ..., 0, -8 (y - b_L)) -- W_L's gradient -2 R a_{L-1}^T is odd in
      the last hidden layer's sites (tanh is odd), R = y - b_L - s n_wL is odd in n_wL, and every
      earlier gradient carries the factor W_L = 0;
    * so grad J_s vanishes at b_L* = mean y exactly (a rational number, by exact summation), and
      the float64 b_L differs from it by the computed amount, which the returned radius covers.

    Returns None for any other point (the hook certifies this one point only)."""
    import fractions

    y = np.asarray(y, np.float64)
    L = arch.depth
    ok_draws = bool(arch.activation == "tanh")
    for name, d in draws.items():
        d = np.asarray(d)
        g = d.reshape(d.shape[0], -1, 4, *d.shape[2:])
        flip_a, flip_b = name in (f"w{L - 1}", f"a{L - 1}"), name == f"w{L}"
        want = [g[:, :, 0] * (sa if flip_a else 1) * (sb if flip_b else 1)
                for sa, sb in ((1, 1), (-1, 1), (1, -1), (-1, -1))]
        ok_draws &= all(np.array_equal(g[:, :, i], want[i]) for i in range(4))
    identity = _trivial_group_identity()
    exact_mean = [sum((fractions.Fraction(float(v)) for v in y[:, j]), fractions.Fraction(0)) / y.shape[0]
                  for j in range(y.shape[1])]

    def certify(w_flat, s):
        layers = unravel(np.asarray(w_flat, np.float64))
        zero = all(np.all(np.asarray(l.W) == 0.0) for l in layers) and all(
            np.all(np.asarray(l.b) == 0.0) for l in layers[:-1])
        if not zero:
            return None
        bL = np.asarray(layers[-1].b, np.float64)
        off = [abs(fractions.Fraction(float(b)) - m) for b, m in zip(bL, exact_mean)]
        radius = np.zeros(np.asarray(w_flat).size)
        radius[-bL.size:] = [float(np.nextafter(float(o), np.inf)) if o else 0.0 for o in off]
        verified = bool(ok_draws and identity[0])
        return dict(verified=True if verified else None, radius=radius,
                    how=(f"exact by symmetry: W and hidden b exactly 0, draws in exact sign groups of four: {ok_draws}, "
                         f"activation tanh: {arch.activation == 'tanh'}; sympy: {identity[1]}; so grad J_s = 0 at "
                         f"b_L* = mean y (exact rational mean), within {fmt_float(float(np.max(radius)))} of the float64 "
                         f"b_L: an exact critical point in that box"))

    return certify


def fmt_float(x: float) -> str:
    return f"{x:.3g}"


def _trivial_group_identity():
    """sympy: the per-draw loss gradient of a 1-2-2 tanh network with biases and noise at every site,
    at W = 0, b1 = 0, summed over the four sign patterns of ((w1, a1), w2), is (0, ..., 0, -8 (y - b2))."""
    import sympy as sp

    from ._symbolic import _network

    net = _network((1, 2, 2), sp.tanh)
    W, b = net["W"], net["b"]
    params = [e for l in (1, 2) for e in list(W[l]) + list(b[l])]
    grads = [sp.diff(net["loss"], p) for p in params]
    at = {e: 0 for l in (1, 2) for e in list(W[l])}
    at.update({e: 0 for e in list(b[1])})
    nw1 = sp.symbols("nw1_1:3")
    na1 = sp.symbols("na1_1:3")
    nw2 = sp.symbols("nw2_1:3")
    total = [0] * len(params)
    for sa, sb in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        flip = {x: sa * x for x in nw1 + na1}
        flip.update({x: sb * x for x in nw2})
        for i, g in enumerate(grads):
            total[i] += g.subs(at).subs(flip, simultaneous=True)
    total = [sp.simplify(t) for t in total]
    y = net["y"]
    want = [0] * (len(params) - 2) + [-8 * (y[0] - b[2][0]), -8 * (y[1] - b[2][1])]
    ok = all(sp.simplify(t - w_) == 0 for t, w_ in zip(total, want))
    return ok, f"group sum of the per-draw gradient at W = 0, b1 = 0 is (0, ..., 0, -8 (y - b2)): {ok}"


def solve_critical(J_mean, w, s, *, maxiter: int = 200):
    """A critical point of the deterministic objective ``J_mean(w, s)`` near ``w`` to float64 precision:
    trust-region Newton (scipy ``trust-exact``, exact Hessian) from ``w``, then Newton polishing steps
    while the gradient shrinks. Returns the flat point (numpy)."""
    from scipy.optimize import minimize

    s = jnp.float64(s)
    f = jax.jit(J_mean)
    g = jax.jit(jax.grad(J_mean))
    H = jax.jit(jax.hessian(J_mean))
    res = minimize(lambda x: float(f(x, s)), np.asarray(w, np.float64), jac=lambda x: np.asarray(g(x, s)),
                   hess=lambda x: np.asarray(H(x, s)), method="trust-exact", options=dict(gtol=1e-14, maxiter=maxiter))
    x = np.asarray(res.x, np.float64)
    best = float(np.max(np.abs(np.asarray(g(x, s)))))
    for _ in range(4):
        step = np.linalg.solve(np.asarray(H(x, s)), np.asarray(g(x, s)))
        x_new = x - step
        gn = float(np.max(np.abs(np.asarray(g(x_new, s)))))
        if not gn < best:
            break
        x, best = x_new, gn
    return x
