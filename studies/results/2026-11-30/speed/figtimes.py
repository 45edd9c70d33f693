"""Each figure's drawing time (wall and CPU s) of ``gift diagnose FILE --no-design`` drawn in one
process.

    python figtimes.py FILE.npz FIGURE_DIR
"""
import sys, time, os, io, contextlib
os.environ["GIFT_FIGURE_PROCESSES"] = "1"
import gift_theory.lab._drawing as Dr
T = []
orig = Dr.draw_to
def timed(drawing, path):
    t0 = time.perf_counter(); c0 = time.process_time()
    try: return orig(drawing, path)
    finally: T.append((os.path.basename(path), time.perf_counter() - t0, time.process_time() - c0))
Dr.draw_to = timed
from gift_theory.cli._main import main
with contextlib.redirect_stdout(io.StringIO()):
    main(["diagnose", sys.argv[1], "--seed", "4", "--no-design", "--quiet", "--figures", sys.argv[2]])
for n, w, c in sorted(T, key=lambda x: -x[1]): print(f"{n:30s} {w:.2f} {c:.2f}")
print("sum", round(sum(w for _, w, _ in T), 2))
