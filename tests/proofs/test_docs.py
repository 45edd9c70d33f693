"""Every code block of docs/theory.md runs: python blocks in order in one namespace, shell
blocks line by line (`gift ...` through the CLI in-process, `python -m linear_case DIR`) -- except
the blocks in ``DUPLICATES``, which a named test already runs on the same kind of instance and
asserts more of (they cost the suite a second compilation of the same rigorous programs)."""

import pytest
import os
import re
import runpy
import shlex
import sys

from gift_theory.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _blocks(text):
    return re.findall(r"```(python|bash)\n(.*?)```", text, flags=re.S)


#: text that identifies a block -> (test file, the test that runs the same call, the call both make)
DUPLICATES = {
    "theorem1_check(jax.random.PRNGKey(1), w0, x, y": (
        "tests/proofs/test_theorem1.py", "def test_theorem1_check_on_linear_network",
        "theorem1_check(kc, params, x, y, gt.awgn(s0), arch, s0, st_, K2=4"),
}


@pytest.mark.slow
def test_theory_md_code_blocks_run(tmp_path, monkeypatch, x64, capsys):
    with open(os.path.join(ROOT, "docs", "theory.md")) as fh:
        blocks = _blocks(fh.read())
    assert blocks and {lang for lang, _ in blocks} == {"python", "bash"}
    os.symlink(os.path.join(ROOT, "proofs_checks"), tmp_path / "proofs_checks")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "docs_theory"}
    skipped = []
    for lang, code in blocks:
        dup = next((d for k, d in DUPLICATES.items() if k in code), None)
        if dup is not None:
            skipped.append(dup)
            continue
        if lang == "python":
            exec(compile(code, "docs/theory.md", "exec"), ns)
            continue
        for line in code.splitlines():
            line = line.split("#")[0].strip()
            if not line:
                continue
            argv = shlex.split(line)
            if argv[0] == "gift":
                assert main(argv[1:]) == 0, line
            elif argv[:3] == ["python", "-m", "linear_case"]:
                monkeypatch.setattr(sys, "argv", ["linear_case"] + argv[3:])
                runpy.run_module("linear_case", run_name="__main__")
            else:
                raise AssertionError(f"docs/theory.md: a shell line the test cannot run: {line}")
    assert (tmp_path / "gift-out" / "theory_check.md").exists()
    assert (tmp_path / "gift-out" / "linear_case" / "bound_regions.png").exists()
    # each skipped block matched once, and its test still exists and makes the same call on the same instance kind
    assert sorted(skipped) == sorted(DUPLICATES.values())
    for path, test, call in skipped:
        with open(os.path.join(ROOT, path)) as fh:
            src = fh.read()
        assert test in src and call in src.split(test, 1)[1].split("\ndef ", 1)[0], (path, test)
