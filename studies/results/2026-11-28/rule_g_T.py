import sys, jax, numpy as np, os
from gift_theory.lab._io import load_measurement
from gift_theory.lab._diagnose import Session, _single, _corr_z
from gift_theory.lab._identify import identify
from gift_theory.lab._mechanisms import named
from gift_theory.lab._shots import model_shots
from gift_theory._model import named_subkey
from gift_theory.lab._qtest import over_inputs
path, seed = sys.argv[1], int(sys.argv[2])
meas = load_measurement(path)
session = Session(jax.random.PRNGKey(seed), meas)
ident = identify(meas)
layers = sorted({int(r["layer"]) for r in ident.rows() if r["class"] in ("gain_fluctuation", "correlated_noise") and named(r, ident.taps)})
cands = session.candidates([_single(c) for c in sys.argv[3:]])
r = meas.r; ids = list(meas.layer_ids()); data = meas.layers()
for l in layers:
    zd = _corr_z(data[ids.index(l)], r)[:, 0]
    res = {}
    for name, model in [("awgn", session.baseline)] + [(c.name, c.model) for c in cands]:
        own = model_shots(named_subkey(session.k_cmp, "corr/" + name), model, meas, 4 * r)
        z = _corr_z(own[ids.index(l)], r); mc, vc = z.mean(1), z.var(1, ddof=1)
        res[name] = ((zd - mc) ** 2, vc)
    db, vb = res["awgn"]
    for name, (dc, vc) in res.items():
        T = over_inputs((dc - 1.25 * vc).mean(1)); tw = over_inputs(((db - vb / 4) - (dc - vc / 4)).mean(1))
        print(os.path.basename(path), "layer", l, name, "T %.1f toward %.1f" % (T, tw), "p_c %.3g" % [c for c in cands if c.name == name][0].comparison.p_value if name != "awgn" else "")
