"""Deep linear networks in closed form: J_s, its minimisers, d/ds grad J, d2/ds2 grad J and
the bounds of Theorem 1 (paper Example ex: linear network, eq. condition finetuning works
linear net).

Weights w = (W_1, ..., W_L), W_l of shape (d_l, d_{l-1}), no biases, product
W = W_L ... W_1. Data: y = V x with E[x x^T] = Sigma (x zero-mean), V of shape (d_L, d_0).
Two noise placements (reference §1 with identity activation):

* ``"input"`` -- the paper's example: a_0 = x + n_a0 only, so
  J_s(w) = tr((V - W) Sigma (V - W)^T) + s^2 ||W||_F^2.
* ``"all"`` -- the paper's ONN model M_s: noise at the input, every weighted sum and
  every hidden activation, so
  J_s(w) = tr((V - W) Sigma (V - W)^T) + s^2 B(w),
  B(w) = ||W_L..W_1||^2 + sum_{l=1}^{L} ||W_L..W_{l+1}||^2 + sum_{l=1}^{L-1} ||W_L..W_{l+1}||^2
  (an empty product is the identity of size d_L).

Both are J_s = A(w) + s^2 B(w), hence d/ds grad J_s = 2 s grad B and
d2/ds2 grad J_s = 2 grad B, independent of zeta.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

MODES = ("input", "all")


class LinearTask(NamedTuple):
    """y = V x with second moment E[x x^T] = Sigma (x zero-mean)."""

    V: np.ndarray       # (d_L, d_0)
    Sigma: np.ndarray   # (d_0, d_0)


def isotropic_task(V, m2: float = 1.0) -> LinearTask:
    """The example's assumption: uncorrelated inputs of equal second moment m2 = E[x_i^2]."""
    V = np.atleast_2d(np.asarray(V, dtype=np.float64))
    return LinearTask(V, m2 * np.eye(V.shape[1]))


def product(ws):
    """W = W_L ... W_1."""
    W = ws[0]
    for Wl in ws[1:]:
        W = Wl @ W
    return W


def _tails(ws):
    """P_l = W_L ... W_{l+1} for l = 0..L (P_L = identity)."""
    d_L = ws[-1].shape[0]
    out = [None] * (len(ws) + 1)
    P = jnp.eye(d_L, dtype=ws[-1].dtype)
    out[len(ws)] = P
    for l in range(len(ws), 0, -1):
        P = P @ ws[l - 1]
        out[l - 1] = P
    return out


def noise_term(ws, mode: str = "input"):
    """B(w): the coefficient of s^2 in J_s (see the module docstring)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}")
    P = _tails(ws)
    B = jnp.sum(P[0] ** 2)  # the input noise passes through W
    if mode == "all":
        L = len(ws)
        B = B + sum(jnp.sum(P[l] ** 2) for l in range(1, L + 1))       # n_w(l)
        B = B + sum(jnp.sum(P[l] ** 2) for l in range(1, L))           # n_a(l), l < L
    return B


def J(ws, s, task: LinearTask, mode: str = "input"):
    """J_s(w) in closed form."""
    D = jnp.asarray(task.V) - product(ws)
    return jnp.trace(D @ jnp.asarray(task.Sigma) @ D.T) + s ** 2 * noise_term(ws, mode)


def J_with_biases(params, s, task: LinearTask, mode: str = "all"):
    """J_s of the linear network *with biases* (the paper's M_s with identity activation):
    params = ((W_1, b_1), ..., (W_L, b_L)); the output adds c = sum_l W_L..W_{l+1} b_l, which is
    independent of the zero-mean input and of the noise, so J_s = J_s(no biases) + ||c||^2."""
    ws = tuple(p[0] for p in params)
    P = _tails(ws)
    c = sum(P[l] @ params[l - 1][1] for l in range(1, len(ws) + 1))
    return J(ws, s, task, mode) + jnp.sum(c ** 2)


@partial(jax.jit, static_argnames=("mode",))
def _derivs(ws, s, V, Sigma, mode):
    task = LinearTask(V, Sigma)
    g = jax.grad(J)(ws, s, task, mode)
    gB = jax.grad(noise_term)(ws, mode)
    flat = lambda t: ravel_pytree(t)[0]
    return flat(g), flat(gB)


def derivatives(ws, s, task: LinearTask, mode: str = "input") -> dict:
    """grad J_s, d/ds grad J_s = 2 s grad B and d2/ds2 grad J_s = 2 grad B (flat vectors)."""
    with jax.enable_x64(True):  # closed forms are mathematics: float64
        ws = tuple(jnp.asarray(W, jnp.float64) for W in ws)
        g, gB = _derivs(ws, jnp.float64(s), jnp.asarray(task.V, jnp.float64), jnp.asarray(task.Sigma, jnp.float64),
                        mode)
        g, gB = np.asarray(g), np.asarray(gB)
    return {"grad": g, "ds_grad": 2 * s * gB, "ds2_grad": 2 * gB, "grad_B": gB}


def product_minimiser(s, task: LinearTask) -> np.ndarray:
    """The minimiser over the product W of the input-noise J_s: V Sigma (Sigma + s^2 I)^-1.

    Every factorisation of it is a critical point of J_s in the factors (``mode="input"``).
    """
    S = np.asarray(task.Sigma)
    return np.asarray(task.V) @ S @ np.linalg.inv(S + s ** 2 * np.eye(S.shape[0]))


def balanced_chain(W: np.ndarray, L: int):
    """A balanced factorisation of a row vector W (1, d) into widths d-1-...-1:
    W_1 = c^{1/L - 1} W (1, d), W_l = c^{1/L} (1, 1), c = ||W||."""
    W = np.atleast_2d(np.asarray(W, dtype=np.float64))
    c = float(np.linalg.norm(W))
    root = c ** (1.0 / L)
    return (W * (root / c),) + tuple(np.array([[root]]) for _ in range(L - 1))


def minimise(ws0, s, task: LinearTask, mode: str = "all", tol: float = 1e-12):
    """A critical point of J_s in the factors near ``ws0`` (BFGS on the closed form)."""
    with jax.enable_x64(True):
        return _minimise(ws0, s, task, mode, tol)


def _minimise(ws0, s, task, mode, tol):
    from scipy.optimize import minimize

    task = LinearTask(jnp.asarray(task.V, jnp.float64), jnp.asarray(task.Sigma, jnp.float64))
    ws0 = tuple(jnp.asarray(W, jnp.float64) for W in ws0)
    flat0, unravel = ravel_pytree(ws0)
    f = jax.jit(lambda v: J(unravel(v), s, task, mode))
    g = jax.jit(jax.grad(lambda v: J(unravel(v), s, task, mode)))
    res = minimize(lambda v: float(f(v)), np.asarray(flat0), jac=lambda v: np.asarray(g(v)), method="BFGS",
                   options={"gtol": tol, "maxiter": 10000})
    return tuple(np.asarray(W) for W in unravel(jnp.asarray(res.x)))


class Bounds(NamedTuple):
    """Theorem 1 at a critical point w0 of J_s0 of a linear network."""

    v_norm: float            # ||d/ds grad J_s0(w0)|| = 2 s0 ||grad B||
    uv: float                # (d2/ds2 grad J)^T v = 4 s0 ||grad B||^2 (any zeta)
    printed_rhs: float       # ||v|| / (1/2 |u^T v|) = 1 / ||grad B||
    corrected_rhs: float     # ||v||^2 / (1/2 |u^T v|) = 2 s0
    example_rhs: float       # eq. condition finetuning works linear net (input noise, isotropic)

    def C1(self, s0: float, st: float) -> float:
        """C1 = grad J_st(w0)^T v = 2 s0 (st^2 - s0^2) ||grad B||^2 exactly."""
        gB2 = (self.v_norm / (2 * s0)) ** 2
        return 2 * s0 * (st ** 2 - s0 ** 2) * gB2


def theorem1_bounds(ws0, s0: float, task: LinearTask, mode: str = "input") -> Bounds:
    """Printed and corrected right-hand sides of ass:Laplacian-properties at w0."""
    d = derivatives(ws0, s0, task, mode)
    v, u = d["ds_grad"], d["ds2_grad"]
    vn = float(np.linalg.norm(v))
    uv = float(u @ v)
    m2 = float(np.mean(np.diag(task.Sigma)))
    Vn = float(np.linalg.norm(task.V))
    return Bounds(vn, uv, vn / (0.5 * abs(uv)), vn ** 2 / (0.5 * abs(uv)), example_rhs(s0, m2, Vn))


def example_rhs(s0, m2, V_norm):
    """The printed bound (1 + s0^2 / E[x_i^2]) / (2 ||V||_2) (eq. condition finetuning works linear net)."""
    return (1.0 + np.asarray(s0) ** 2 / m2) / (2.0 * V_norm)


def chain_printed_rhs(s0, L: int, V_norm: float, m2: float = 1.0):
    """The printed Theorem-1 RHS 1/||grad B(w0)|| for the example (input noise), balanced
    chain d-1-..-1, w0 the balanced factorisation of V m2/(m2+s0^2). Vectorised in s0.

    ||grad B|| = 2 sqrt(L) c^{2 - 1/L},  c = ||W0|| = m2 ||V|| / (m2 + s0^2).
    """
    c = m2 * V_norm / (m2 + np.asarray(s0, dtype=np.float64) ** 2)
    return 1.0 / (2.0 * np.sqrt(L) * c ** (2.0 - 1.0 / L))
