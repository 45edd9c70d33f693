"""The compact tanh ONN shared by the numerical checks: teacher data, w0 at s0, and Theorem 1
at (s0, st) checked on it with :func:`proofs_checks.theorem1` (a numeric family: per-input
losses over fixed noise draws, whose mean is the objective); built once per process."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

import gift_theory as gt

from . import _mc
from ._family import family
from ._family_check import theorem1
from ._record import hypothesis

_CACHE: dict = {}

#: the instance: s0 = 0.1 and st = 0.13, where both the printed and the corrected condition
#: of Theorem 1 hold at the checks' level (at st = 0.3 the printed one does not)
S0, ST = 0.1, 0.13


class Setup(NamedTuple):
    problem: _mc.Problem
    w0: tuple
    s0: float
    st: float
    theorem1: dict
    wt: tuple
    K2: int = 16
    J: object = None            # the family's per-input losses J(w_flat, s) -> (n,), whose mean is the objective


def onn_family(n: int = 1024, K2: int = 16, s0: float = S0, steps: int = 1500):
    """The 3-4-2 tanh ONN as a numeric Theorem-1 family.

    Returns (J, w0_flat, wt_flat, problem, w0 params, wt params, certify): ``J(w, s)`` gives the
    per-input losses (n,) of M_s at flat weights ``w`` over K2 fixed standard draws per input
    (pathwise in s; sign-symmetric groups of four, :func:`_mc.symmetric_draws`), so the objective
    J_s(w) = mean of those n values is a finite mean; w0 trains at s0 on the n teacher points (the
    data measure mu) and is then solved to a critical point of that objective at s0 (trust-region
    Newton, float64 precision); wt is the trivial point (W = 0, hidden b = 0, b_L = mean y), a
    degenerate critical point of J_s for every s, proved so by ``certify``
    (:func:`_mc.trivial_point_certificate`).
    """
    with jax.enable_x64(True):
        arch = gt.Architecture((3, 4, 2))
        prob = _mc.teacher_problem(jax.random.PRNGKey(11), arch, n=n, s=s0)
        trained = _mc.train_critical(jax.random.PRNGKey(12), prob, s0, K2=32, steps=steps)
        draws = _mc.symmetric_draws(jax.random.PRNGKey(13), arch, prob.physics, n, K2)
        flat, unravel = ravel_pytree(trained)
        wt = _mc.trivial_critical_point(arch, prob.y)
        wt_flat = np.asarray(ravel_pytree(wt)[0])
        x = jnp.asarray(prob.x, jnp.float64)[:, None, :]         # float64: the objective is a float64 finite mean
        y = jnp.asarray(prob.y, jnp.float64)[:, None, :]

    def J(w, s):
        out = gt.forward(unravel(w), x, draws, prob.physics.replace(s=s), arch).y
        return jnp.mean(jnp.sum((y - out) ** 2, axis=-1), axis=1)

    with jax.enable_x64(True):
        w0_flat = _mc.solve_critical(lambda w, s: jnp.mean(J(w, s)), np.asarray(flat), s0)
        w0 = unravel(jnp.asarray(w0_flat))
    certify = _mc.trivial_point_certificate(arch, draws, prob.y, unravel)
    return J, w0_flat, wt_flat, prob, w0, wt, certify


#: the instance's sizes (teacher points, fixed draws per input, Adam steps before Newton): "full" for
#: ``gift check``, "precise" for ``--precise``, "quick" for the tests (the same architecture, teacher,
#: noise levels and seeds on fewer points and draws; other numbers, and Eval's comparisons, whose standard
#: error is the spread over the points, resolve less: algorithm1_stopping_rule's paired test and
#: theorem2_guarantee's K_large are undecided there)
SIZES = {"full": (1024, 16, 1500), "precise": (1024, 32, 3000), "quick": (256, 8, 500)}


def setup(precise: bool = False, s0: float = S0, st: float = ST, *, quick: bool = False) -> Setup:
    """Arch 3-4-2 tanh, 1024 teacher points (the data measure mu), w0 a critical point of the
    finite-mean objective at s0 (16 fixed sign-symmetric draws per input; ``precise``: 32),
    Theorem 1 at (s0, st) on that objective (every decision from rigorous enclosures).
    ``quick``: the test instance of :data:`SIZES` (256 points, 8 draws per input)."""
    size = "quick" if quick else ("precise" if precise else "full")
    k = (size, s0, st)
    if k not in _CACHE:
        n, K2, steps = SIZES[size]
        J, w0f, wtf, prob, w0, wt, certify = onn_family(n=n, K2=K2, s0=s0, steps=steps)
        th1 = theorem1(family(J, w0f, wt=wtf, name="tanh ONN 3-4-2", certify=certify), s0, st)
        _CACHE[k] = Setup(prob, w0, s0, st, th1, wt, K2, J)
    return _CACHE[k]


def mc_size(st_: Setup, K2: int, *, per_input_spread: bool = False) -> dict:
    """The Monte-Carlo size of a check's evaluation on the instance ``st_``: ``K2`` draws per input
    on the full instances. On a smaller one (quick) a paired difference on mu (only the noise is
    random) gets as many more draws per input as keep n K2, its precision, the same;
    ``per_input_spread``: an estimate whose standard error is the spread of per-input values over
    sqrt(n) (Eval's comparisons) -- more draws per input would not buy its precision back, so ``K2``
    stays. Off the full instances one chunk per evaluation (fewer dispatches; other draws than at
    full size). Returns keywords {"K2", "chunk"} for :func:`proofs_checks._gift.make_eval` and
    :func:`proofs_checks._mc.paired_difference_on_mu`."""
    n = st_.problem.x.shape[0]
    scale = 1 if per_input_spread else max(1, SIZES["full"][0] // n)
    full = n >= SIZES["full"][0]
    return dict(K2=K2 * scale, chunk=4096 if full else n * K2 * scale)


def hypotheses_of_theorem1(th1: dict) -> list:
    """Theorem 1's hypotheses on the ONN instance, as verified by :func:`proofs_checks.theorem1`."""
    out = [hypothesis(h["name"], h["statement"], h["verified"], str(h["detail"])) for h in th1["hypotheses"]]
    out.append(hypothesis("corrected_condition", "the corrected condition (||v||_2^2 in the numerator)",
                          th1["corrected_condition"] == "holds", th1["corrected_condition"],
                          needed_for_refutation=False))
    return out
