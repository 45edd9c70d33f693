import sys, importlib.util, json
import numpy as np
spec = importlib.util.spec_from_file_location("ti", "tests/lab/test_identify.py")
ti = importlib.util.module_from_spec(spec); spec.loader.exec_module(ti)
from gift_theory.lab._identify import identify
import gift_theory
out = open(sys.argv[1], "w")
for seed in range(int(sys.argv[2]), int(sys.argv[3])):
    m = ti.sim(2000 + seed, widths=(6, 12, 8, 4), n=80, r=16, s=0.05, taps=True, interleaved=True)
    ident = identify(m)
    rows = ident.rows()
    mechs = ti._first(ident)
    out.write(json.dumps({"seed": seed, "min_p_adj": min(r["p_adj"] for r in rows),
                          "mechs": [x["mechanism"] for x in mechs], "code": gift_theory.__file__}) + "\n"); out.flush()
