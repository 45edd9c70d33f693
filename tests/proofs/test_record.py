"""The verdict machinery: each rule can return every verdict on cases with a known truth."""

import pytest

from proofs_checks import equality_verdict, record, sign_verdict


def test_equality_verdict_three_outcomes():
    assert equality_verdict(1.0, 0.01, 1.0)[0] == "fails"          # 100 se away
    assert equality_verdict(0.001, 0.01, 1.0)[0] == "holds"        # within error, powerful test
    assert equality_verdict(0.001, 0.5, 1.0)[0] == "inconclusive"  # within error, no power


def test_sign_verdict_three_outcomes():
    assert sign_verdict(-1.0, 0.01, "negative")[0] == "holds"
    assert sign_verdict(1.0, 0.01, "negative")[0] == "fails"
    assert sign_verdict(-0.01, 1.0, "negative")[0] == "inconclusive"
    assert sign_verdict(1.0, 0.01, "positive")[0] == "holds"


def test_combine_all_parts():
    from proofs_checks import _record            # through the module: the mutation pass replaces its attributes

    assert _record.combine("holds", "holds") == "holds"
    assert _record.combine("holds", "inconclusive") == "inconclusive"          # every part must hold
    assert _record.combine("inconclusive", "fails", "holds") == "fails"       # one failing part refutes


def test_record_requires_evidence_for_fails():
    with pytest.raises(ValueError):
        record("x", "c", "fails", "e")
    with pytest.raises(ValueError):
        record("x", "c", "maybe", "e")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0})
    assert set(r) == {"id", "claim", "verdict", "evidence", "correction", "counterexample", "hypotheses"}


def test_no_refutation_outside_the_hypotheses():
    from proofs_checks._record import hypothesis

    outside = hypothesis("B2", "...", False, "the box binds")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [outside])
    assert r["verdict"] == "inconclusive" and "outside the statement's hypotheses: B2" in r["evidence"]
    finding = hypothesis("B2 (other instance)", "...", False, "reported", needed_for_refutation=False)
    assert record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [finding])["verdict"] == "fails"


def test_levels_split_the_family_wise_error():
    from proofs_checks import FAMILY_ALPHA, level
    from proofs_checks._record import SHARES

    lv = level(4)
    assert lv.alpha * 4 * SHARES == pytest.approx(FAMILY_ALPHA)
    assert lv.z2 > lv.z1 > 0 and "family-wise" in lv.text()


def test_refutation_needs_every_hypothesis_verified_and_says_so():
    from proofs_checks._record import assumed, hypothesis

    undecided = hypothesis("w0_critical", "...", None, "not resolved")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [undecided])
    assert r["verdict"] == "inconclusive" and "not verified" in r["evidence"] and "w0_critical" in r["evidence"]
    ok = hypothesis("w0_critical", "...", True, "exact")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [ok])
    assert r["verdict"] == "fails" and "inside the statement's hypotheses: w0_critical verified" in r["evidence"]
    assert record("x", "c", "inconclusive", "e", hypotheses=[undecided])["evidence"] == "e"
    # an assumed hypothesis is null, says so, and cannot carry a refutation
    a = assumed("A3", "fresh draws", "by construction of the sampler")
    assert a["verified"] is None and a["assumed"] is True and a["detail"].startswith("assumed")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [ok, a])
    assert r["verdict"] == "inconclusive" and "A3" in r["evidence"]
    with pytest.raises(ValueError):                                  # assumed and "verified" contradict
        record("x", "c", "holds", "e", hypotheses=[dict(a, verified=True)])


def test_property_no_fails_with_an_unverified_needed_hypothesis():
    """Whatever the hypotheses (verified True / False / None, assumed or not, needed or not), a record
    says "fails" only when every needed hypothesis is verified True and none of them is assumed."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from proofs_checks._record import assumed, hypothesis

    one = st.one_of(
        st.builds(lambda v, n: hypothesis("h", "s", v, "d", needed_for_refutation=n),
                  st.sampled_from([True, False, None]), st.booleans()),
        st.builds(lambda n: assumed("h", "s", "why", needed_for_refutation=n), st.booleans()))

    @settings(max_examples=300, deadline=None)
    @given(st.lists(one, max_size=6), st.sampled_from(["holds", "fails", "inconclusive"]))
    def prop(hyps, verdict):
        r = record("x", "c", verdict, "e", "fix", {"d": 1}, hyps)
        needed = [h for h in r["hypotheses"] if h["needed_for_refutation"]]
        if r["verdict"] == "fails":
            assert all(h["verified"] is True and not h["assumed"] for h in needed)
        if verdict == "fails" and any(h["verified"] is not True for h in needed):
            assert r["verdict"] == "inconclusive"
        if verdict != "fails":
            assert r["verdict"] == verdict

    prop()


def test_no_hypothesis_is_set_true_or_false_by_hand():
    """No call of ``hypothesis(...)`` in a check module passes a literal True/False as ``verified``:
    a hypothesis is computed on the instance, or it is ``assumed(...)`` (null)."""
    import ast
    import pathlib

    import proofs_checks

    root = pathlib.Path(proofs_checks.__file__).parent
    hits = []
    for p in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) in (
                    "hypothesis", "_hyp"):
                args = list(node.args[2:3]) + [k.value for k in node.keywords if k.arg == "verified"]
                hits += [f"{p.name}:{node.lineno}" for a in args
                         if isinstance(a, ast.Constant) and isinstance(a.value, bool)]
    assert hits == []


def test_no_literal_verdicts_in_the_checks():
    """Verdicts come from decide()/the verdict rules: no check module assigns a verdict string."""
    import pathlib
    import re

    import proofs_checks

    root = pathlib.Path(proofs_checks.__file__).parent
    pat = re.compile(r"verdict\s*=\s*[\"'](holds|fails|inconclusive)[\"']")
    hits = [f"{p.name}: {m.group(0)}" for p in root.glob("*.py") for m in pat.finditer(p.read_text())]
    assert hits == []


def test_the_report_keeps_a_bar_in_the_evidence_a_bar():
    from proofs_checks._report import render_markdown

    rec = {"id": "x", "verdict": "holds", "claim": "c", "evidence": "P(B|A) = 0.5", "hypotheses": [],
           "correction": None, "counterexample": None}
    md = render_markdown([rec])
    row = next(l for l in md.splitlines() if l.startswith("| `x`"))
    assert "P(B\\|A)" in row and row.count(" | ") == 3  # escaped: the table keeps its four cells
    assert "**Evidence.** P(B|A) = 0.5" in md            # the record in full, as written
