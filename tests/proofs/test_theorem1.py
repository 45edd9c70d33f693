"""Theorem 1: the random smooth families with the intermediate-value argument, the records
on exact families, and the user-facing ONN checker on a deep linear network whose answers are
known in closed form."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

import gift_theory as gt
import linear_case as lc
from proofs_checks import _theorem1 as T
from proofs_checks import theorem1_check

vec = st.lists(st.floats(-10, 10), min_size=3, max_size=3)


@given(v=vec, u=vec, c=vec, s0=st.floats(0.01, 2.0), d=st.floats(-2.0, 2.0))
def test_corrected_condition_implies_descent(v, u, c, s0, d):
    st_ = s0 + d
    d = st_ - s0          # the step actually taken in floating point
    if st_ <= 0 or d == 0 or np.linalg.norm(v) < 1e-6:
        return
    q = T.family_quantities(v, u, c, s0, st_)
    if q["gap"] < (1 - 1e-9) * q["corrected_rhs"]:   # strictly inside, beyond rounding
        assert q["C1"] * d > 0


def test_wrong_sign_gives_a_zero_of_C1_inside_the_printed_condition():
    """1-D, v = 1/2, u = 1, s0 = 2, st = 0.9: C1(st) has the wrong sign; st* = 1 is the zero."""
    q = T.family_quantities([0.5], [1.0], [0.0], 2.0, 0.9)
    assert q["gap"] < q["printed_rhs"] and q["C1"] > 0          # wrong sign (st < s0)
    st_star, printed_there = T.nearest_zero_of_C1([0.5], [1.0], [0.0], 2.0, 0.9)
    assert abs(st_star - 1.0) < 1e-12 and printed_there
    assert abs(T.family_quantities([0.5], [1.0], [0.0], 2.0, st_star)["C1"]) < 1e-12


def test_search_counts():
    r = T.search_families(jax.random.PRNGKey(0), n=1500)
    assert r["wrong_sign_printed"] > 0 and r["zero_inside"] == r["wrong_sign_printed"]
    assert r["bad_corrected"] == 0 and r["n_corrected"] > 100


def test_condition_record():
    r = T.theorem1_condition(jax.random.PRNGKey(1))
    assert r["verdict"] == "fails" and r["counterexample"]["C1"] == "0" and r["correction"]
    assert all(h["verified"] for h in r["hypotheses"])


def test_theorem1_check_on_linear_network(x64):
    """Input-noise linear network 2-1-1 at its balanced critical point: v = 2 s0 grad B,
    C1 = 2 s0 (st^2 - s0^2) ||grad B||^2 and the corrected rhs 2 s0 are known exactly."""
    s0, st_ = 0.3, 0.5
    task = lc.isotropic_task([[0.6, -0.8]], 1.0)
    ws = lc.balanced_chain(lc.product_minimiser(s0, task), 2)
    exact = lc.theorem1_bounds(ws, s0, task)
    arch = gt.Architecture((2, 1, 1), activation="identity", noise_sites="input")
    params = tuple(gt.Layer(jnp.asarray(W), jnp.zeros((W.shape[0],))) for W in ws)
    kx, kc = jax.random.split(jax.random.PRNGKey(3))
    x = np.asarray(jax.random.normal(kx, (2048, 2), jnp.float64))
    y = x @ task.V.T
    res = theorem1_check(kc, params, x, y, gt.awgn(s0), arch, s0, st_, K2=4, confidence=1 - 1e-4)
    for name, truth in (("v_norm2", exact.v_norm ** 2), ("C1", exact.C1(s0, st_))):
        iv = res[name]
        assert iv["lo"] <= truth <= iv["hi"], (name, iv, truth)
    assert res["corrected_rhs"]["lo"] <= 2 * s0 <= res["corrected_rhs"]["hi"]
    assert res["corrected_condition"] in ("holds", "undecided")
    assert res["confirmed"]


def test_trivial_point_is_critical_and_bad(x64):
    """W = 0, hidden b = 0, b_L = mean y: grad J_s = 0 within error at any s (tanh)."""
    from proofs_checks import _mc
    from proofs_checks._record import z_crit

    arch = gt.Architecture((2, 3, 2))
    prob = _mc.teacher_problem(jax.random.PRNGKey(5), arch, n=512, s=0.3)
    wt = T.trivial_critical_point(arch, prob.y)
    noise = _mc.draws(jax.random.PRNGKey(6), arch, prob.physics, 512, 8)
    g = _mc.estimate(_mc.per_input("grad", wt, 0.3, prob.x, prob.y, noise, prob.physics, arch))
    nz = g.se > 0
    assert np.all(g.mean[~nz] == 0)
    assert np.max(np.abs(g.mean[nz] / g.se[nz])) < z_crit(1 - 1e-5 / g.mean.size)
