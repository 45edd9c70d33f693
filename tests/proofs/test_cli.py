"""gift check: --json follows CONTRACTS §4; bad input is one line and exit status 2."""

import json

from gift_theory.cli._main import main

KEYS = {"id", "claim", "verdict", "evidence", "correction", "counterexample"}


def test_json_and_report(tmp_path, capsys):
    report = tmp_path / "out" / "r.md"
    rc = main(["check", "--json", "--only", "backprop_formulas", "--only", "lemma_gaussian_product_derivative",
               "--report", str(report)])
    out = capsys.readouterr()
    assert rc == 0
    obj = json.loads(out.out)
    assert list(obj) == ["checks"] and [c["id"] for c in obj["checks"]] == ["backprop_formulas",
                                                                            "lemma_gaussian_product_derivative"]
    for c in obj["checks"]:
        assert set(c) == KEYS and c["verdict"] in ("holds", "fails", "inconclusive")
    text = report.read_text()
    assert "## lemma_gaussian_product_derivative: fails" in text and "Correction" in text


def test_bad_input_exit_2(tmp_path, capsys):
    assert main(["check", "--only", "no_such_check"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no_such_check" in err and "Traceback" not in err
    assert main(["check", "--report", str(tmp_path)]) == 2      # a folder, not a file
    assert main(["check", "--bogus"]) == 2
