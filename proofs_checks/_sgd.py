"""Propositions 1-2 (thm:stochastic-approximation-theorem-limit-trajectories / -limitpoints):
limit points of projected SGD (eq. projected-sgd) on the box H."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

import gift_theory as gt

from . import _mc
from ._record import fmt, record, z_crit


def projected_sgd(key, problem, s, box, *, steps=20000, batch=16, eps0=0.05, k0=1000.0, power=0.75, init=None):
    """Projected SGD w <- p_H(w - eps_k grad (y - M_s(x, w, N))^2) with fresh data and noise
    per step, eps_k = eps0 (1 + k/k0)^-power (sum eps = inf, sum eps^2 < inf); returns the last
    iterate and the average of the last quarter."""
    arch = problem.arch
    x = jnp.asarray(problem.x)
    y = jnp.asarray(problem.y)
    w = init if init is not None else gt.init_params(jax.random.fold_in(key, 0), arch, dtype=jnp.float64)
    phys = problem.physics.replace(s=s)

    def loss(p, xb, yb, nb):
        return jnp.mean(jnp.sum((yb - gt.forward(p, xb, nb, phys, arch).y) ** 2, -1))

    @jax.jit
    def run(w):
        def step(c, k):
            w, avg = c
            kk = jax.random.fold_in(key, k + 1)
            idx = jax.random.randint(kk, (batch,), 0, x.shape[0])
            nb = gt.sample_noise(jax.random.fold_in(kk, 1), arch, phys, (batch,), jnp.float64)
            g = jax.grad(loss)(w, x[idx], y[idx], nb)
            eps = eps0 * (1.0 + k / k0) ** (-power)
            w = gt.project(jax.tree_util.tree_map(lambda a, b: a - eps * b, w, g), box)
            on = (k >= 3 * steps // 4).astype(jnp.float64)
            avg = jax.tree_util.tree_map(lambda a, b: a + on * b / (steps - 3 * steps // 4), avg, w)
            return (w, avg), None
        zero = jax.tree_util.tree_map(jnp.zeros_like, w)
        (w, avg), _ = jax.lax.scan(step, (w, zero), jnp.arange(steps))
        return w, avg

    return run(w)


def kkt_analysis(grad_mean, grad_se, w_flat, box_lo, box_hi, atol=1e-3):
    """Split coordinates into active (at a bound) and interior; z-scores of the gradient."""
    at_hi = np.abs(w_flat - box_hi) < atol
    at_lo = np.abs(w_flat - box_lo) < atol
    active = at_hi | at_lo
    z = grad_mean / grad_se
    return dict(active=active, at_hi=at_hi, at_lo=at_lo, z=z)


def sgd_limit_points(key=None, precise: bool = False) -> dict:
    key = jax.random.PRNGKey(7) if key is None else key
    with jax.enable_x64(True):
        arch = gt.Architecture((2, 3, 1))
        prob = _mc.teacher_problem(jax.random.PRNGKey(41), arch, n=256, s=0.1)
        # the teacher has gain 2: its weights exceed the box, so the box is active
        box = gt.Box(-0.5, 0.5, -0.5, 0.5)
        w_last, w_avg = projected_sgd(key, prob, 0.1, box, steps=40000 if precise else 20000)
        K2 = 512 if precise else 256
        noise = _mc.draws(jax.random.fold_in(key, 99), arch, prob.physics, prob.x.shape[0], K2)
        g = _mc.estimate(_mc.per_input("grad", w_avg, 0.1, prob.x, prob.y, noise, prob.physics, arch))
        flat = np.asarray(gt.flatten(w_avg)[0])
    lo = np.concatenate([np.full(l.W.size, box.W_min).ravel().tolist() + np.full(l.b.size, box.b_min).tolist()
                         for l in w_avg])
    hi = -lo  # symmetric box
    a = kkt_analysis(np.asarray(g.mean), np.asarray(g.se), flat, lo, hi)
    P = flat.size
    zc = z_crit(1 - 1e-5 / P)   # Bonferroni over coordinates
    act, inner = a["active"], ~a["active"]
    gabs = np.abs(np.asarray(g.mean))
    max_active = float(gabs[act].max()) if act.any() else 0.0
    max_inner = float(gabs[inner].max()) if inner.any() else 0.0
    sig_active = act.any() and bool(np.any(np.abs(a["z"][act]) > zc))
    # printed: grad J = 0 at the limit; fails if an active coordinate has a significant gradient
    # an order of magnitude above the interior residual (the residual of a finite run)
    refuted = sig_active and max_active > 10 * max_inner
    if act.any():
        verdict = "fails" if refuted else "inconclusive"
    else:  # no active bound: the printed statement is the KKT condition; test grad = 0
        verdict = "holds" if not np.any(np.abs(a["z"]) > zc) else "inconclusive"
    # KKT: no significant violation -- grad <= 0 at an upper bound (the descent direction points
    # out of H), grad >= 0 at a lower bound -- and the interior residual small against the active gradients
    kkt_sign = bool(np.all(a["z"][a["at_hi"]] < zc) and np.all(a["z"][a["at_lo"]] > -zc))
    kkt_ok = bool(kkt_sign and max_inner < 0.1 * max_active) if act.any() else False
    ce = None
    if verdict == "fails":
        i = int(np.argmax(np.where(act, np.abs(a["z"]), -1)))
        ce = {"coordinate": i, "value": float(flat[i]), "bound": float(hi[i] if a["at_hi"][i] else lo[i]),
              "grad": float(g.mean[i]), "se": float(g.se[i]), "max_abs_grad_interior": max_inner}
    return record(
        "sgd_limit_points",
        "thm:stochastic-approximation-theorem-limitpoints (Proposition 2) and Result 1: projected SGD "
        "(eq. projected-sgd) converges to a point of {w : grad_w J_s|_H (w) = 0}",
        verdict,
        f"tanh ONN {arch}, teacher (gain 2) data n=256, box [-0.5, 0.5], s=0.1, {40000 if precise else 20000} "
        f"projected SGD steps (eps_k = 0.05 (1+k/1000)^-0.75), tail average: {int(act.sum())}/{P} coordinates at "
        f"the box; grad J_s there up to {fmt(max_active)} (max |z| = "
        f"{float(np.abs(a['z'][act]).max()) if act.any() else 0:.1f}), interior max |grad| {fmt(max_inner)} "
        f"(Bonferroni z_crit {zc:.1f}); no significant KKT sign violation at the bounds: {kkt_sign}",
        correction=("the limit points are KKT points of J_s on H: grad J_s = 0 in the interior coordinates, "
                    "grad <= 0 at an upper and >= 0 at a lower bound (the projected gradient vanishes: "
                    "-grad J + pi = 0); verified here (no significant sign violation at the bounds, interior "
                    "residual < 10% of the active gradients)") if kkt_ok else None,
        counterexample=ce)
