"""``gift diagnose FILE --seed 4 --no-design --figures DIR`` in this process, its whole time and
the wall and CPU seconds of its ``save_figures`` (drawing and writing the PNGs and netCDF files).

    PYTHONPATH=CHECKOUT python studies/results/2026-11-30/figures/figtime.py FILE.npz DIR LABEL
"""
import sys, time, io, contextlib
import matplotlib; matplotlib.use("agg")
import gift_theory.lab._figure_sets as FS
T = {}
orig_save = FS.save_figures
def timed(*a, **k):
    t0 = time.perf_counter(); c0 = time.process_time()
    try: return orig_save(*a, **k)
    finally: T['save'] = (time.perf_counter() - t0, time.process_time() - c0)
FS.save_figures = timed
from gift_theory.cli._main import main
t0 = time.perf_counter()
with contextlib.redirect_stdout(io.StringIO()):
    main(["diagnose", sys.argv[1], "--seed", "4", "--no-design", "--figures", sys.argv[2]])
print(sys.argv[3], "total", round(time.perf_counter() - t0, 2), "save_figures wall/cpu", [round(x, 2) for x in T['save']])
