import sys, importlib.util, json
import numpy as np
spec = importlib.util.spec_from_file_location("ti", "tests/lab/test_identify.py")
ti = importlib.util.module_from_spec(spec); spec.loader.exec_module(ti)
from gift_theory.lab._identify import identify
out = open(sys.argv[1], "w")
for seed in range(int(sys.argv[2]), int(sys.argv[3])):
    rng = np.random.default_rng(seed)
    L = int(rng.integers(2, 5))
    widths = tuple(int(w) for w in rng.integers(3, 20, L + 1))
    n = int(rng.choice([80, 120, 240])); r = int(rng.choice([16, 32, 64])); s = float(rng.uniform(0.02, 0.12))
    m = ti.sim(1000 + seed, widths=widths, n=n, r=r, s=s, taps=False)
    ident = identify(m)
    c = {x.name: x for x in ident.output_candidates}
    mechs = ti._first(ident)
    out.write(json.dumps({"seed": seed, "widths": widths, "n": n, "r": r, "s": s, "prog_z": c["programmed"].z,
                          "mechs": [x["mechanism"] for x in mechs]}) + "\n"); out.flush()
