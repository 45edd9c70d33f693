"""The teaching notebooks in docs/notebooks run from top to bottom without error.

Each notebook's key cells ``assert`` what it teaches (a condition computed false, a loss that
falls, a prediction with the realised sign), so a notebook that runs is a notebook whose claims
held on this run. The notebooks are stored without outputs; the kernel inherits the test
environment (a temporary weight cache, no persistent compilation cache).
"""

import glob
import os
import time

import nbformat
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NOTEBOOKS = sorted(glob.glob(os.path.join(ROOT, "docs", "notebooks", "*.ipynb")))


def test_there_are_at_least_four_notebooks_stored_without_outputs():
    assert len(NOTEBOOKS) >= 4
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        nbformat.validate(nb)
        code = [c for c in nb.cells if c.cell_type == "code"]
        assert code and all(not c.outputs and c.execution_count is None for c in code), path
        assert any("assert " in c.source for c in code), f"{path}: no cell asserts anything"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    t0 = time.perf_counter()
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    print(f"{os.path.basename(path)}: {time.perf_counter() - t0:.0f} s")
