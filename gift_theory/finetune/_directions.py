"""In-silico search directions (free: no chip use). All computed on the training data at
the model's physics (awgn at s0), with the draws of :mod:`gift_theory._random`."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import _random
from .._errors import require
from ..estimators import d_ds_grad, grad_objective, hvp
from ._tree import axpy, norm, scale, vdot

DIRECTIONS = ("score_paper", "score", "pathwise", "gradient", "random", "ift")


def hvp_operator(problem, *, K2: int = 4, key=None):
    """v -> Hess_w J_s0(w0) v at fixed draws (a linear map), and its draws' key."""
    key = jax.random.fold_in(problem.key, 301) if key is None else key

    def op(v):
        return hvp(key, problem.w0, problem.x, problem.y, problem.model, problem.arch, v, K2=K2).mean

    return op


def conjugate_gradients(op, b, *, iters: int = 30, damping: float = 0.0, tol: float = 1e-6):
    """Solve (H + damping I) v = b by CG; stop early at negative curvature (returns the iterate)."""
    x = scale(0.0, b)
    r = b
    p = r
    rr = vdot(r, r)
    b_norm = jnp.sqrt(rr)
    info = {"iterations": 0, "negative_curvature": False}
    for k in range(iters):
        Ap = axpy(damping, p, op(p))
        pAp = vdot(p, Ap)
        if pAp <= 0:
            info["negative_curvature"] = True
            if k == 0:
                x = b
            break
        a = rr / pAp
        x = axpy(a, p, x)
        r = axpy(-a, Ap, r)
        rr_new = vdot(r, r)
        info["iterations"] = k + 1
        if jnp.sqrt(rr_new) < tol * b_norm:
            break
        p = axpy(rr_new / rr, p, r)
        rr = rr_new
    info["residual"] = float(jnp.sqrt(rr) / b_norm)
    return x, info


def direction(problem, kind: str, *, K2: int = 16):
    """A search direction shaped like the weights, and a dict of what was done.

    kind : "score_paper" (the printed D^[0], unscaled), "score" and "pathwise" (d/ds grad J_s0),
        "gradient" (grad J_s0 on all training data), "random" (Gaussian), "ift" (the
        minimiser-path tangent H^-1 d/ds grad J_s0 by conjugate gradients)
    """
    require(kind in DIRECTIONS, f"direction: unknown kind {kind!r}; known: {', '.join(DIRECTIONS)}")
    return problem.insilico("direction", (kind, int(K2)), lambda: _direction(problem, kind, int(K2)))


def _direction(problem, kind: str, K2: int):
    key = jax.random.fold_in(problem.key, 100 + DIRECTIONS.index(kind))
    args = (problem.w0, problem.x, problem.y, problem.model, problem.arch)
    if kind in ("score_paper", "score", "pathwise"):
        est = d_ds_grad(key, *args, method=kind, K2=K2 if kind == "pathwise" else 4 * K2)
        return est.mean, {"se_norm": float(norm(est.se)), "norm": float(norm(est.mean))}
    if kind == "gradient":
        est = grad_objective(key, *args, K2=K2)
        return est.mean, {"se_norm": float(norm(est.se)), "norm": float(norm(est.mean))}
    if kind == "random":
        leaves, tree = jax.tree_util.tree_flatten(problem.w0)
        ks = jax.random.split(jax.random.fold_in(problem.key, 999), len(leaves))
        return jax.tree_util.tree_unflatten(tree, [_random.normal_like_jax(k, l.shape, l.dtype) for k, l in zip(ks, leaves)]), {}
    g = d_ds_grad(key, *args, method="pathwise", K2=K2).mean
    op = hvp_operator(problem)
    rayleigh = float(vdot(g, op(g)) / vdot(g, g))
    v, info = conjugate_gradients(op, g, damping=1e-2 * abs(rayleigh))
    info["rayleigh"] = rayleigh
    return v, info
