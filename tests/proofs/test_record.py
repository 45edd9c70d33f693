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
    with pytest.raises(ValueError):
        record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [outside])
    finding = hypothesis("B2 (other instance)", "...", False, "reported", needed_for_refutation=False)
    assert record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [finding])["verdict"] == "fails"


def test_levels_split_the_family_wise_error():
    from proofs_checks import FAMILY_ALPHA, level
    from proofs_checks._record import SHARES

    lv = level(4)
    assert lv.alpha * 4 * SHARES == pytest.approx(FAMILY_ALPHA)
    assert lv.z2 > lv.z1 > 0 and "family-wise" in lv.text()


def test_refutation_needs_every_hypothesis_verified_and_says_so():
    from proofs_checks._record import hypothesis

    undecided = hypothesis("w0_critical", "...", None, "not resolved")
    with pytest.raises(ValueError):
        record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [undecided])
    ok = hypothesis("w0_critical", "...", True, "exact")
    r = record("x", "c", "fails", "e", "fix", {"diff": 1.0}, [ok])
    assert "inside the statement's hypotheses: w0_critical verified" in r["evidence"]
    assert record("x", "c", "inconclusive", "e", hypotheses=[undecided])["evidence"] == "e"


def test_no_literal_verdicts_in_the_checks():
    """Verdicts come from decide()/the verdict rules: no check module assigns a verdict string."""
    import pathlib
    import re

    import proofs_checks

    root = pathlib.Path(proofs_checks.__file__).parent
    pat = re.compile(r"verdict\s*=\s*[\"'](holds|fails|inconclusive)[\"']")
    hits = [f"{p.name}: {m.group(0)}" for p in root.glob("*.py") for m in pat.finditer(p.read_text())]
    assert hits == []
