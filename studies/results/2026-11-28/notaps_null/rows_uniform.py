import sys, json, importlib.util
import numpy as np, jax
spec = importlib.util.spec_from_file_location("ti", "tests/lab/test_identify.py")
ti = importlib.util.module_from_spec(spec); spec.loader.exec_module(ti)
import gift_theory as gt
from gift_theory.lab import _identify as I, simulate_measurement
import gift_theory.lab._explain_output as EO
EO.explain = lambda meas, s: []
out = open(sys.argv[1], "w")
for seed in range(int(sys.argv[2]), int(sys.argv[3])):
    rng = np.random.default_rng(seed)
    L = int(rng.integers(2, 5))
    widths = tuple(int(w) for w in rng.integers(3, 20, L + 1))
    n = int(rng.choice([80, 120, 240])); r = int(rng.choice([16, 32, 64])); s = float(rng.uniform(0.02, 0.12))
    Ws, bs = ti._net(1000 + seed, widths)
    params = tuple(gt.Layer(np.asarray(W), np.asarray(b)) for W, b in zip(Ws, bs))
    x = np.random.default_rng(seed + 1).uniform(0, 1, (n, widths[0]))
    m = simulate_measurement(jax.random.PRNGKey(seed), params, x, gt.Physics.create(s=s, uniform=True), shots=r, taps=False)
    ident = I.identify(m)
    rows = [dict(cls=x["class"], test=x["test"], p=x["p"], z=x.get("z"), p_adj=x["p_adj"]) for x in ident.rows()]
    out.write(json.dumps({"seed": seed, "widths": widths, "n": n, "r": r, "s": s, "rows": rows}) + "\n"); out.flush()
