"""``gift diagnose FILE --seed 4 --no-design --figures DIR`` in this process; the wall seconds of
the whole command and of its figure stage (``diagnosis_figures``: the figures' numbers, the
netCDF files and the drawings), with ``GIFT_FIGURE_PROCESSES`` as set.

    GIFT_FIGURE_PROCESSES=2 python figure_stage.py FILE.npz DIR LABEL
"""
import contextlib
import io
import sys
import time

import gift_theory.lab as lab

T = {}
orig = lab.diagnosis_figures


def timed(*a, **k):
    t0 = time.perf_counter()
    try:
        return orig(*a, **k)
    finally:
        T["figures"] = time.perf_counter() - t0


lab.diagnosis_figures = timed
from gift_theory.cli._main import main  # noqa: E402

t0 = time.perf_counter()
with contextlib.redirect_stdout(io.StringIO()):
    main(["diagnose", sys.argv[1], "--seed", "4", "--no-design", "--quiet", "--figures", sys.argv[2]])
print(sys.argv[3], "command", round(time.perf_counter() - t0, 2), "figure stage", round(T["figures"], 2))
