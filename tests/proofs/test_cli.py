"""gift check: --json follows CONTRACTS §4; bad input is one line and exit status 2."""

import json

from gift_theory.cli import main

KEYS = {"id", "claim", "verdict", "evidence", "correction", "counterexample", "hypotheses"}


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


def test_theorem1_subcommand_quartic_json(capsys):
    from proofs_checks.families import path

    rc = main(["check", "theorem1", "--family", path("quartic"), "--s0", "1", "--st", "1.1", "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert rc == 0 and set(obj) == {"printed_condition", "corrected_condition", "C1", "conclusion", "evidence",
                                    "hypotheses", "inside_hypotheses", "counterexample"}
    assert obj["inside_hypotheses"] is True and obj["counterexample"] is True
    assert all(h["verified"] is True for h in obj["hypotheses"])
    assert obj["printed_condition"] is True and obj["corrected_condition"] is False
    assert obj["C1"] == 0.0 and obj["conclusion"] == "fails" and "counterexample to Theorem 1" in obj["evidence"]


def test_theorem1_subcommand_bad_input(tmp_path, capsys):
    from proofs_checks.families import path

    bad = tmp_path / "fam.py"
    bad.write_text("import sympy as sp\ns = sp.Symbol('s')\nw = sp.Symbol('w')\nq = sp.Symbol('q')\nJ = q * w + s\nw0 = 0\n")
    for argv in (["check", "theorem1", "--family", str(bad), "--s0", "1", "--st", "2"],          # extra symbol
                 ["check", "theorem1", "--family", str(tmp_path / "none.py"), "--s0", "1", "--st", "2"],
                 ["check", "theorem1", "--family", path("quartic"), "--s0", "0", "--st", "2"],   # s0 not > 0
                 ["check", "theorem1", "--s0", "1", "--st", "2"],
                 ["check", "--family", path("quartic")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err


BAD_FAMILIES = {
    "syntax.py": "import sympy as sp\ns = sp.Symbol('s'\n",                                 # syntax error
    "names.py": "import sympy as sp\ns = sp.Symbol('s')\nw = sp.Symbol('w')\n",             # no J, no w0
    "exits.py": "raise SystemExit(3)\n",                                                  # the file exits
    "numpy_J.py": "import numpy as np\ndef J(w, s):\n    return np.sum(np.asarray(w) ** 2) * s\nw0 = [1.0, 2.0]\n",
    "undefined.py": "import sympy as sp\ns, w = sp.symbols('s w')\nJ = w**2/2 + sp.Function('f')(s)*w\nw0 = 0\n",
    "complex.py": "import sympy as sp\ns, w = sp.symbols('s w')\nJ = w**2/2 + sp.I*s*w\nw0 = 0\n",
    "kink.py": "import sympy as sp\ns, w = sp.symbols('s w')\nJ = sp.Abs(w) + (s - 1)*w\nw0 = 0\n",
    "log.py": "import sympy as sp\ns, w = sp.symbols('s w')\nJ = sp.log(w) + s*w\nw0 = 0\n",   # not finite at w0
}


def test_theorem1_bad_family_files_exit_2_one_line(tmp_path, capsys):
    """Every broken family file: exit status 2, one line naming the file, no traceback."""
    for name, text in BAD_FAMILIES.items():
        f = tmp_path / name
        f.write_text(text)
        assert main(["check", "theorem1", "--family", str(f), "--s0", "1", "--st", "1.1", "--json"]) == 2, name
        out = capsys.readouterr()
        assert out.out == "" and out.err.count("\n") == 1 and "Traceback" not in out.err, (name, out.err)
        assert name in out.err, out.err

