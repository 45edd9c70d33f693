"""Pickle every drawing of a gift diagnose run: python capture_drawings.py FILE.npz FIGURE_DIR OUT.pkl"""
import sys, os, io, contextlib, pickle
os.environ["GIFT_FIGURE_PROCESSES"] = "1"
import gift_theory.lab._drawing as Dr
orig = Dr.draw_to
allj = []
def cap(drawing, path):
    allj.append((drawing, os.path.basename(path)))
    return orig(drawing, path)
Dr.draw_to = cap
from gift_theory.cli._main import main
with contextlib.redirect_stdout(io.StringIO()):
    main(["diagnose", sys.argv[1], "--seed", "4", "--no-design", "--quiet", "--figures", sys.argv[2]])
pickle.dump(allj, open(sys.argv[3], "wb"))
