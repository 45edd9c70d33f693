"""The Theorem-1 checker on families whose answers are known: the quartic family, the linear
closed forms (sympy against linear_case, and a numeric JAX copy against the sympy result), and
a small tanh ONN."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import sympy as sp

import linear_case as lc
from proofs_checks import contract_json, family, load_family, theorem1
from proofs_checks.families import path


def test_quartic_exact():
    r = theorem1(load_family(path("quartic")), 1, "1.1")
    assert contract_json(r) == {"printed_condition": True, "corrected_condition": False, "C1": 0.0,
                                "conclusion": "fails", "evidence": r["evidence"], "hypotheses": r["hypotheses"],
                                "inside_hypotheses": True, "counterexample": True}
    assert math.isclose(r["printed_rhs"]["value"], 2 / 10.1) and math.isclose(r["corrected_rhs"]["value"], 0.84 / 10.1)
    assert r["critical_points_st"] == [["0"]] and r["J_st_wt_minus_J_st_w0"] == [0.0]
    assert all(h["verified"] for h in r["hypotheses"])
    # a step away from 1.1: C1 != 0 and a descent step exists
    r2 = theorem1(load_family(path("quartic")), 1, "1.05")
    assert r2["C1"]["value"] != 0 and r2["descent"]["exists"] is True


def test_linear_chains_against_closed_forms():
    for L in (1, 2):
        e = lc.symbolic_example(L)
        num = {e["V"]: sp.Rational(1, 2), e["m2"]: 1}
        c = sp.Rational(1, 2) / (1 + sp.Rational(1, 4))
        fam = family(e["J"].subs(num), [c ** sp.Rational(1, L)] * L, s=e["s"], w=list(e["w"]))
        r = theorem1(fam, "0.5", "0.8")
        ws = lc.balanced_chain(lc.product_minimiser(0.5, lc.isotropic_task([[0.5]], 1.0)), L)
        b = lc.theorem1_bounds(ws, 0.5, lc.isotropic_task([[0.5]], 1.0))
        assert math.isclose(r["corrected_rhs"]["value"], 1.0) and math.isclose(r["printed_rhs"]["value"], b.printed_rhs)
        assert math.isclose(r["C1"]["value"], b.C1(0.5, 0.8), rel_tol=1e-12)
        assert r["conclusion"] == ("holds" if L == 1 else "fails")      # L = 2: the saddle w = 0


def test_numeric_copy_matches_sympy(x64):
    """The depth-2 chain as a JAX function: the same C1 and ||v||^2, a rigorous sup bracket around
    the exact sup, and exact (K = 1) intervals of width 0."""
    sym = theorem1(load_family(path("linear_chain")), "0.5", "0.8")
    c = 0.5 / 1.25

    def J(w, s):
        W = w[0] * w[1]
        return (0.5 - W) ** 2 + s ** 2 * W ** 2

    num = theorem1(family(J, np.full(2, math.sqrt(c))), 0.5, 0.8)
    for k in ("C1", "v_norm2"):
        assert math.isclose(num[k]["value"], sym[k]["value"], rel_tol=1e-9)
    s = num["sup_abs_d2_dot_v"]
    assert s["lo"] <= sym["sup_abs_d2_dot_v"]["value"] * (1 + 1e-12) and sym["sup_abs_d2_dot_v"]["value"] <= s["hi"]
    assert num["printed_condition"] == sym["printed_condition"] and num["corrected_condition"] == sym["corrected_condition"]
    # w0 lies on the curve w1 w2 = 0.4 of critical points: degenerate, so it is not certified (and says why)
    crit = next(h for h in num["hypotheses"] if h["name"] == "w0_critical")
    assert crit["verified"] is None and "degenerate" in crit["detail"]


@pytest.mark.slow
def test_trivial_point_certificate(x64):
    """The trivial point of a tanh ONN (W = 0, hidden b = 0, b_L = mean y) is a degenerate critical point,
    which Krawczyk's test cannot certify; with sign-symmetric draws the finite-mean objective keeps the
    symmetry that makes it exactly critical, and the certificate proves it (exact checks, sympy) --
    with plain draws it proves nothing. Independent: the float64 gradient at the point."""
    import gift_theory as gt
    from jax.flatten_util import ravel_pytree
    from proofs_checks import _mc
    from proofs_checks._theorem1 import trivial_critical_point

    arch = gt.Architecture((2, 3, 2))
    prob = _mc.teacher_problem(jax.random.PRNGKey(1), arch, n=16, s=0.2)
    wt_p = trivial_critical_point(arch, prob.y)
    wt, unravel = ravel_pytree(wt_p)
    x, y = jnp.asarray(prob.x, jnp.float64)[:, None, :], jnp.asarray(prob.y, jnp.float64)[:, None, :]
    grads = {}
    for name, draws in (("symmetric", _mc.symmetric_draws(jax.random.PRNGKey(3), arch, prob.physics, 16, 8)),
                        ("plain", _mc.draws(jax.random.PRNGKey(3), arch, prob.physics, 16, 8))):
        cert = _mc.trivial_point_certificate(arch, draws, prob.y, unravel)
        c = cert(np.asarray(wt), 0.25)
        Jm = lambda w: jnp.mean(jnp.sum((y - gt.forward(unravel(w), x, draws, prob.physics.replace(s=0.25),
                                                               arch).y) ** 2, axis=-1))
        grads[name] = float(jnp.max(jnp.abs(jax.grad(Jm)(wt))))
        assert c["verified"] is (True if name == "symmetric" else None), (name, c["how"])
        assert np.all(c["radius"][:-2] == 0) and np.all(c["radius"][-2:] < 1e-15)     # only b_L is rounded
    assert grads["symmetric"] < 1e-14 < 1e-3 < grads["plain"]
    assert _mc.trivial_point_certificate(arch, draws, prob.y, unravel)(np.asarray(wt) + 0.1, 0.25) is None


def test_per_sample_non_critical_family_is_outside_never_a_counterexample(x64, capsys):
    """The per-sample family's objective is the mean of its K values: its gradient at w0 is computed
    (-0.05 in w1), so w0 is not critical -- reported outside the hypotheses, never a counterexample
    (before, a z-test that failed to reject made it "verified"). Through the command, on the shipped
    file. The same family at the critical w0 = (0, 1) is a counterexample to Theorem 1 as printed
    (the saddle at w2 = 0)."""
    import json

    from gift_theory.cli import main

    fam = load_family(path("per_sample"))
    assert main(["check", "theorem1", "--family", path("per_sample"), "--s0", "1", "--st", "1.5", "--json"]) == 0
    j = json.loads(capsys.readouterr().out)
    crit = next(h for h in j["hypotheses"] if h["name"] == "w0_critical")
    assert crit["verified"] is False and "-0.05" in crit["detail"]
    assert j["conclusion"] == "fails" and j["inside_hypotheses"] is False and j["counterexample"] is False
    assert "no counterexample" in j["evidence"] and "a counterexample to Theorem 1 as printed" not in j["evidence"]
    # the objective's gradient, computed independently: d/dw1 mean_i J_i = w1 - mean(a) = -0.05 at w0
    g = jax.grad(lambda w: jnp.mean(fam.J(w, 1.0)))(jnp.array([-0.05, 1.0]))
    assert np.allclose(g, [-0.05, 0.0], atol=1e-15)
    # at the critical point (0, 1): inside every hypothesis, and the saddle refutes the conclusion
    r2 = theorem1(family(fam.J, [0.0, 1.0], wt=[-0.175, 0.0]), 1.0, 1.5)
    assert contract_json(r2)["inside_hypotheses"] is True and contract_json(r2)["counterexample"] is True
    dj = r2["wt"][0]["J_st_wt_minus_J_st_w0"]            # independent: 0.25 - 0.175^2/2 + (0 - 0) at w1* = -0.175
    assert dj["lo"] <= 0.25 - 0.175 ** 2 / 2 <= dj["hi"]


@pytest.mark.slow
def test_a_decimal_w0_is_not_critical_exactly_and_the_check_says_why_and_what_to_do():
    s, w = sp.Symbol("s", positive=True), sp.Symbol("w", real=True)
    J = (w - sp.sqrt(2) * s) ** 2 + s ** 2 * w ** 4 / 10
    w0 = float(sp.nsolve(sp.diff(J, w).subs(s, 1), w, 1.3))  # a critical point to a float's precision
    detail = next(h["detail"] for h in theorem1(family(J, w0, s=s, w=w), "1", "1.1")["hypotheses"]
                  if h["name"] == "w0_critical")
    assert "zero to a float's precision, not exactly" in detail and "sp.Rational" in detail
    far = next(h for h in theorem1(family(J, 1.0, s=s, w=w), "1", "1.1")["hypotheses"] if h["name"] == "w0_critical")
    assert far["verified"] is False and "float's precision" not in far["detail"]  # really not critical: no hint
