"""Time and profile where.png drawn alone, from the drawings capture_drawings.py pickled:

    python where_profile.py OUT.png DRAWINGS.pkl
"""
import pickle, time, cProfile, pstats, os
import matplotlib; matplotlib.use("agg")
from gift_theory.lab._drawing import draw_to
import sys; OUT=sys.argv[1]
d = {n: dr for dr, n in pickle.load(open(sys.argv[2], "rb"))}["where.png"]
draw_to(d, OUT + ".warm.png")  # warm fonts
t = time.perf_counter(); draw_to(d, OUT); print("draw", time.perf_counter() - t)
pr = cProfile.Profile(); pr.enable(); draw_to(d, OUT + ".profiled.png"); pr.disable()
pstats.Stats(pr).sort_stats("cumulative").print_stats(35)
