"""Every section the package, the docs and the notebooks cite exists, and none cites the internal
contract: users are sent to docs/reference.md (its §1..§8, as every ``--help`` numbers them), and
a citation of ``plugins.md §7`` to that page's own numbered sections."""

import glob
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PACKAGES = ("gift_theory", "linear_case", "proofs_checks", "paper_figures", "studies")
#: "§2b", "reference §4", "(docs/plugins.md §7", "reference.md) §3"; the page a citation names, if any
CITATION = re.compile(r"(?:([\w-]+)\.md\)?\s*)?§\s*(\d+[a-z]?)")
#: "reference section 6", "docs/reference.md section 4"
WORDED = re.compile(r"reference(?:\.md)?\)?,? section (\d+[a-z]?)")


def _files():
    out = [os.path.join(ROOT, "README.md")]
    for pkg in PACKAGES:
        out += glob.glob(os.path.join(ROOT, pkg, "**", "*.py"), recursive=True)
        out += glob.glob(os.path.join(ROOT, pkg, "**", "*.md"), recursive=True)
    out += glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)
    out += glob.glob(os.path.join(ROOT, "docs", "**", "*.ipynb"), recursive=True)
    out += glob.glob(os.path.join(ROOT, "docs", "*.sh"))
    return sorted(set(out))


def _sections(page: str) -> set:
    """The sections of a docs page: "§N" headers (reference.md) or "## N." headers (the others)."""
    with open(os.path.join(ROOT, "docs", page + ".md"), encoding="utf-8") as fh:
        text = fh.read()
    return set(re.findall(r"^#+ §(\d+[a-z]?)\b", text, re.M)) | set(re.findall(r"^#+ (\d+[a-z]?)\.", text, re.M))


def _citations(text: str):
    """(page, section) of every citation in ``text``; page "reference" when the citation names none."""
    for m in CITATION.finditer(text):
        page = (m.group(1) or "reference").split("/")[-1]
        yield page, m.group(2)
    for m in WORDED.finditer(text):
        yield "reference", m.group(1)


def test_the_reference_has_every_contract_section():
    assert {"1", "2", "2b", "3", "4", "5", "5b", "6", "7", "8"} <= _sections("reference")


def test_every_cited_section_exists_and_nothing_cites_the_internal_contract():
    files = _files()
    assert len(files) > 100, "the scan found the package"
    pages, missing, contract = {}, [], []
    for path in files:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        rel = os.path.relpath(path, ROOT)
        if "CONTRACTS" in text:
            contract.append(rel)
        for page, sec in _citations(text):
            if page not in pages:
                pages[page] = _sections(page) if os.path.exists(os.path.join(ROOT, "docs", page + ".md")) else None
            if pages[page] is not None and sec not in pages[page]:
                missing.append(f"{rel}: {page} §{sec}")
    assert not contract, f"cite docs/reference.md, not the internal contract: {contract}"
    assert not missing, f"citations of sections that do not exist: {sorted(set(missing))}"


def test_the_scan_would_catch_a_missing_section():
    # the same scan on a text citing a section the reference lacks, and one of plugins.md's own
    cites = list(_citations("see reference §9 and (docs/plugins.md §7), reference section 5b"))
    assert cites == [("reference", "9"), ("plugins", "7"), ("reference", "5b")]
    assert "9" not in _sections("reference") and "7" in _sections("plugins")
