"""correlated_noise's statistics on random null networks (the generator of notaps_null/rows_null.py)."""
import sys, json, re, importlib.util
import numpy as np
spec = importlib.util.spec_from_file_location("ti", "tests/lab/test_identify.py")
ti = importlib.util.module_from_spec(spec); spec.loader.exec_module(ti)
from gift_theory.lab import _identify as I
import gift_theory.lab._explain_output as EO
EO.explain = lambda meas, s: []
out = open(sys.argv[1], "w")
taps = sys.argv[4] == "taps"
extra = sys.argv[5] if len(sys.argv) > 5 else ""
for seed in range(int(sys.argv[2]), int(sys.argv[3])):
    rng = np.random.default_rng(seed)
    L = int(rng.integers(2, 5))
    widths = tuple(int(w) for w in rng.integers(3, 20, L + 1))
    n = int(rng.choice([80, 120, 240])); r = int(rng.choice([16, 32, 64])); s = float(rng.uniform(0.02, 0.12))
    kw = {}
    if extra == "common":   # common additive noise at the output's input layer: c xi on every neuron
        kw = dict(common=(L - 1 if L > 1 else 1, 0.5 * s))
    m = ti.sim(1000 + seed, widths=widths, n=n, r=r, s=s, taps=taps, **kw)
    rows = I.identify(m).rows()
    for x in rows:
        if x["class"] == "correlated_noise":
            g = re.search(r"z = (-?[0-9.]+|-?inf|nan) common(?:, (-?[0-9.]+|-?inf|nan) any pattern)?", x["evidence"])
            out.write(json.dumps({"seed": seed, "widths": widths, "n": n, "r": r, "layer": x["layer"], "p": x["p"],
                                  "p_adj": x["p_adj"], "z1": float(g.group(1)),
                                  "zu": float(g.group(2)) if g.group(2) else None}) + "\n"); out.flush()
