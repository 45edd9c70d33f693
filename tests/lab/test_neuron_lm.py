"""The per-neuron Levenberg-Marquardt fit of per-neuron offsets (biases, per-neuron parameters)."""

import jax
import jax.numpy as jnp
import numpy as np

# private: the per-neuron LM kernel against closed-form and BFGS solutions (a fit mixes it with the noise)
from gift_theory.lab import _offset_fit as fo


def test_neuron_lm_is_the_ridge_solution_of_a_linear_problem():
    # pred_i = J_i d_i per neuron (P = 2 values per neuron): the minimiser of
    # 0.5 inv_v |t_i - J_i d_i|^2 + 0.5 sum_p lam_p d_pi^2 is the ridge solution, neuron by neuron
    rng = np.random.default_rng(0)
    P, S, n = 2, 50, 7
    J = rng.normal(size=(P, S, n))
    truth = rng.normal(size=(P, n))
    target = np.einsum("psi,pi->si", J, truth) + 0.1 * rng.normal(size=(S, n))
    inv_v, lam = 4.0, np.array([0.5, 2.0])

    def linearised(ds):
        d = np.stack([np.asarray(x, np.float64) for x in ds])
        return np.einsum("psi,pi->si", J, d), J

    got = np.stack(fo._neuron_lm(linearised, [np.zeros(n), np.zeros(n)], target, inv_v, list(lam)))
    for i in range(n):
        A = inv_v * J[:, :, i] @ J[:, :, i].T + np.diag(lam)
        want = np.linalg.solve(A, inv_v * J[:, :, i] @ target[:, i])
        # the fit works on float32 values: agreement to float32 rounding of the solution
        np.testing.assert_allclose(got[:, i], want, rtol=1e-5, atol=1e-6)


def test_neuron_lm_solves_a_saturating_nonlinear_problem_like_a_general_optimiser():
    # pred = tanh(z + d) per neuron (a bias offset through a saturating activation), d large
    rng = np.random.default_rng(1)
    S, n = 80, 5
    z = rng.normal(size=(S, n))
    d_true = np.array([1.5, -2.0, 0.3, 0.0, 0.8])
    target = np.tanh(z + d_true) + 0.02 * rng.normal(size=(S, n))
    inv_v, lam = 1.0 / 0.02 ** 2, 1.0

    @jax.jit
    def lin(d):
        p = jnp.tanh(jnp.asarray(z, jnp.float32) + d[0])
        return p, (1.0 - p ** 2)[None]

    got = fo._neuron_lm(lambda ds: lin(tuple(ds)), [np.zeros(n)], target, inv_v, [lam])[0]

    from scipy import optimize

    def loss(d):
        r = target - np.tanh(z + d)
        return 0.5 * inv_v * np.sum(r * r) + 0.5 * lam * np.sum(d * d)

    ref = optimize.minimize(loss, np.zeros(n), method="BFGS", options={"gtol": 1e-8}).x
    # standard error of each value ~ 0.02 / sqrt(S * mean tanh'^2): agree to a small part of it
    np.testing.assert_allclose(got, ref, atol=2e-4)
    assert loss(got) <= loss(ref) + 1e-3
