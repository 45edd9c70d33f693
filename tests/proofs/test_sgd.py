"""Propositions 1-2: the closed form they rest on, the exact (A4) and (B2) bookkeeping."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
import linear_case as lc
from proofs_checks import _sgd


@pytest.mark.slow
def test_closed_form_with_biases_matches_monte_carlo(x64):
    rng = np.random.default_rng(0)
    arch = gt.Architecture((2, 2, 1), activation="identity", noise_sites="all")
    params = tuple(gt.Layer(jnp.asarray(rng.normal(size=(arch.widths[l], arch.widths[l - 1]))),
                            jnp.asarray(rng.normal(size=arch.widths[l]))) for l in (1, 2))
    task = lc.isotropic_task([[0.6, -0.8]], 1.0)
    x = jax.random.normal(jax.random.PRNGKey(0), (40000, 2), jnp.float64)
    est = gt.objective(jax.random.PRNGKey(1), params, x, x @ jnp.asarray(task.V).T, gt.awgn(0.4), arch, K2=4)
    closed = float(lc.J_with_biases(params, 0.4, task, "all"))
    assert abs(float(est.mean) - closed) < 4.5 * float(est.se)


def test_step_size_hypothesis_decided_by_sympy():
    assert _sgd.steps_hypothesis(0.05, 100.0, 1.0)["verified"] is True
    assert _sgd.steps_hypothesis(0.05, 100.0, 0.75)["verified"] is True
    assert _sgd.steps_hypothesis(0.05, 100.0, 0.4)["verified"] is False      # sum eps^2 diverges
    assert _sgd.steps_hypothesis(0.05, 100.0, 1.5)["verified"] is False      # sum eps converges


def test_exact_gradient_vanishes_at_the_interior_minimiser(x64):
    s = 0.5
    W = jnp.asarray(np.asarray(lc.isotropic_task([[0.6, -0.8]]).V) / (1 + s ** 2))
    params = (gt.Layer(W, jnp.zeros((1,))),)
    assert float(jnp.max(jnp.abs(_sgd.exact_grad(params, s)))) < 1e-12
    clipped = (gt.Layer(jnp.clip(W, -0.5, 0.5), jnp.zeros((1,))),)
    assert float(jnp.linalg.norm(_sgd.exact_grad(clipped, s))) > 0.3       # the binding box: (B2) fails there
