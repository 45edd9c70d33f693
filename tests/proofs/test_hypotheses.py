"""Hypotheses are computed on the instance (issue 27): the (A1) test can fail, the Theorem-1 family
checker decides criticality by the whole gradient, instances outside a statement never refute it,
Theorem 2 as printed is refuted only inside its hypotheses, and the new checks' computations."""

import json
import math

import numpy as np
import pytest
import sympy as sp

from proofs_checks import contract_json, family, theorem1


# ---------------------------------------------------------------------------------- fixtures
def _saddle_J(w, s):
    """The audit's family: grad J_s0(w0) = (0, -2) at w0 = [1, 1], s0 = 1 -- w0 is not critical,
    yet grad J_s0(w0) . v = 0."""
    return (w[0] - s) ** 2 - w[1] ** 2


@pytest.fixture
def saddle_numeric():
    return family(_saddle_J, [1.0, 1.0], wt=[1.5, 0.0])


@pytest.fixture
def saddle_sympy():
    s = sp.Symbol("s", positive=True)
    w = sp.symbols("w1 w2", real=True)
    return family((w[0] - s) ** 2 - w[1] ** 2, [1, 1], s=s, w=list(w))


def _chain_J(w, s):
    W = w[0] * w[1]
    return (0.5 - W) ** 2 + s ** 2 * W ** 2


# ---------------------------------------------------------------------------------- item 1, 5
def test_non_critical_w0_is_outside_never_a_counterexample(x64, saddle_numeric, saddle_sympy):
    for fam in (saddle_numeric, saddle_sympy):
        r = theorem1(fam, 1, "1.5")
        j = contract_json(r)
        crit = next(h for h in r["hypotheses"] if h["name"] == "w0_critical")
        assert crit["verified"] is False, crit
        assert j["inside_hypotheses"] is False and j["counterexample"] is False
        assert "a counterexample to Theorem 1" not in r["evidence"] and "no counterexample" in r["evidence"]


def test_st_equal_s0_is_outside(x64):
    r = theorem1(family(_chain_J, np.full(2, math.sqrt(0.4)), wt=[0.0, 0.0]), 0.5, 0.5)
    j = contract_json(r)
    assert r["conclusion"] == "fails"                       # a fact about the family ...
    assert j["inside_hypotheses"] is False and j["counterexample"] is False       # ... not a refutation
    assert next(h for h in j["hypotheses"] if h["name"] == "st_ne_s0")["verified"] is False
    assert "outside the theorem's hypotheses" in r["evidence"]
    json.dumps(j)                                           # JSON-ready


def _sqrt2_J(w, s):
    """At s = 1 its critical points are (+-sqrt(2), 1), (0, 1): irrational, so w0 given in float64 is only the
    rounding of one."""
    return (w[0] ** 2 - 2) ** 2 / 4 + (w[1] - s) ** 2 / 2 + (s - 1) * w[0]


def test_rounded_critical_points_are_certified_by_krawczyk(x64):
    """w0 = (sqrt(2) rounded, s0) leaves a gradient of rounding size: Krawczyk's test proves an exact critical
    point within a few ulp (verified True, with the box); a point off by 1e-6 has a gradient whose enclosure
    excludes 0 (verified False: outside). Independent: the exact critical point solves w^3 - 2w + s - 1 = 0."""
    import sympy as sp

    r = theorem1(family(_sqrt2_J, [math.sqrt(2.0), 1.0]), 1.0, 1.5)
    crit = next(h for h in r["hypotheses"] if h["name"] == "w0_critical")
    assert crit["verified"] is True and "Krawczyk" in crit["detail"]
    radius = r["w0_certificate"]["radius"]
    assert 0 < radius < 1e-12
    w = sp.Symbol("w")
    exact = max(float(x) for x in sp.real_roots(sp.Poly(w ** 3 - 2 * w, w)))     # s0 = 1: w1* = sqrt(2)
    assert abs(exact - math.sqrt(2.0)) <= radius
    r2 = theorem1(family(_sqrt2_J, [math.sqrt(2.0) + 1e-6, 1.0]), 1.0, 1.5)
    assert next(h for h in r2["hypotheses"] if h["name"] == "w0_critical")["verified"] is False
    assert contract_json(r2)["inside_hypotheses"] is False


def test_per_sample_J_of_wrong_shape_is_refused(tmp_path, capsys):
    from gift_theory.cli import main

    f = tmp_path / "shape32.py"
    f.write_text("import jax.numpy as jnp\ndef J(w, s):\n    return jnp.ones((3, 2)) * w[0] * s\nw0 = [1.0]\n")
    assert main(["check", "theorem1", "--family", str(f), "--s0", "1", "--st", "1.5", "--json"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and "(3, 2)" in out.err and "Traceback" not in out.err


def test_cli_family_json_says_outside(tmp_path, capsys):
    from gift_theory.cli import main

    f = tmp_path / "saddle.py"
    f.write_text("def J(w, s):\n    return (w[0] - s) ** 2 - w[1] ** 2\nw0 = [1.0, 1.0]\nwt = [1.5, 0.0]\n")
    assert main(["check", "theorem1", "--family", str(f), "--s0", "1", "--st", "1.5", "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["inside_hypotheses"] is False and obj["counterexample"] is False
    assert any(h["name"] == "w0_critical" and h["verified"] is False for h in obj["hypotheses"])


# ---------------------------------------------------------------------------------- item 3
def test_a1_is_computed_on_the_activation_and_can_fail():
    from proofs_checks._hypotheses import activation_pb

    z = sp.Symbol("z", real=True)
    assert activation_pb("identity")["verified"] is True
    assert activation_pb("sin")["verified"] is True
    assert activation_pb(z + z ** 2 / 2)["verified"] is True
    assert activation_pb(sp.exp(z ** 2))["verified"] is False            # faster than every polynomial
    assert activation_pb(sp.Max(z, 0))["verified"] is False              # sigma' jumps
    assert activation_pb("no_such")["verified"] is None
    assert "sin" in activation_pb("sin")["detail"]


def test_lemma_hypotheses_use_the_architecture_and_data():
    import gift_theory as gt
    from proofs_checks._sampling import lemma_hypotheses_onn

    x = np.linspace(0, 1, 12).reshape(4, 3)
    hs = lemma_hypotheses_onn(gt.Architecture((3, 2), activation="sin"), x, x[:, :2])
    assert [h["name"] for h in hs] == ["A1", "A2", "A4"] and all(h["verified"] is True for h in hs[:2])
    assert "sin" in hs[0]["detail"]
    # (A4) concerns SGD's step sizes, which the sampling lemmas do not involve: assumed, never carrying a refutation
    assert hs[2]["assumed"] and hs[2]["verified"] is None and not hs[2]["needed_for_refutation"]
    bad = x.copy()
    bad[0, 0] = np.inf
    assert lemma_hypotheses_onn(gt.Architecture((3, 2), activation="sin"), bad, x[:, :2])[1]["verified"] is False


def test_box_and_keys_and_moments_are_computed():
    import gift_theory as gt
    from proofs_checks._hypotheses import box_hypothesis, distinct_keys, normal_moments

    box = gt.Box(-1.0, 1.0, -1.0, 1.0)
    mask = np.array([True, True, False])
    assert box_hypothesis(box, [0.5, -0.5, 0.1], mask)["verified"] is True
    assert box_hypothesis(box, [1.5, -0.5, 0.1], mask)["verified"] is False
    keys = np.arange(20, dtype=np.uint32).reshape(10, 2)
    assert distinct_keys(keys)["verified"] is True
    assert distinct_keys(np.concatenate([keys, keys[:1]]))["verified"] is False
    assert normal_moments(2, powers=(1, 2))["verified"] is True


def test_sgd_step_keys_are_distinct_across_segments(x64):
    """The replicate runner folds the global step index into each run's key (segments used to restart it)."""
    import jax

    from proofs_checks._hypotheses import distinct_keys
    from proofs_checks._sgd import step_keys

    assert distinct_keys(step_keys(jax.random.PRNGKey(0), 3, 40))["verified"] is True


# ---------------------------------------------------------------------------------- item 2
def test_theorem2_as_printed_is_refuted_inside_its_hypotheses(x64):
    from proofs_checks._gift import theorem2_printed

    rows = {(r["name"], str(r["st"])): r for r in theorem2_printed()}
    for k in (("counterexample", "1"), ("quartic", "1.1")):
        r = rows[k]
        names = {h["name"]: h["verified"] for h in r["res"]["hypotheses"]}
        assert all(names[n] is True for n in ("s_positive", "st_ne_s0", "w0_critical", "printed_condition",
                                              "wt_exists")), names
        assert r["global_min"] is True and r["res"]["corrected_condition"] != "holds"
        assert r["runs"] and all(d > 0 for _, d, _ in r["runs"])     # Algorithm 1 returns a worse point
    same = rows[("quartic", "1")]                                    # s0 = st: outside, reported only
    assert next(h for h in same["res"]["hypotheses"] if h["name"] == "st_ne_s0")["verified"] is False


# ---------------------------------------------------------------------------------- item 6
def test_vector_linear_example_corrected_bound_is_free_of_V():
    from proofs_checks._linear import vector_example

    e = vector_example(2)
    assert e["setting"] == 0 and all(c == 0 for c in e["critical"])
    assert sp.simplify(e["corrected_rhs"] - 2 * e["s0"]) == 0
    assert all(sp.diff(e["printed_rhs"], v) != 0 for v in e["V"])       # the printed one depends on V


def test_report_table_counts_assumed_hypotheses():
    from proofs_checks import record, render_table
    from proofs_checks._record import assumed, hypothesis

    r = record("x", "c", "holds", "e", hypotheses=[hypothesis("a", "s", True, "d"), assumed("b", "s", "why")])
    t = render_table([r])
    assert "1/2 1 assumed" in t and "assumed" in t.splitlines()[-1]


@pytest.mark.slow
def test_a_real_check_cannot_fail_on_an_assumed_hypothesis(monkeypatch):
    """hierarchical_borel_cantelli refutes the proof step inside its (computed) hypothesis; with that
    hypothesis replaced by an assumed one, the same check can only say "inconclusive"."""
    from proofs_checks import _sampling_proofs
    from proofs_checks._record import assumed

    assert _sampling_proofs.hierarchical_borel_cantelli()["verdict"] == "fails"
    monkeypatch.setattr(_sampling_proofs, "normal_moments",
                        lambda *a, **k: assumed("integrability", "E|f| < inf, E f^2 < inf", "not computed"))
    r = _sampling_proofs.hierarchical_borel_cantelli()
    assert r["verdict"] == "inconclusive" and "integrability" in r["evidence"]
