"""Dump identify() of each guard file: every row and each layer's arrays (for an exact before/after diff)."""
import json, sys, numpy as np
from gift_theory.lab import identify, load_measurement
out = {}
for f in sys.argv[2:]:
    ident = identify(load_measurement(f))
    out[f] = {"rows": ident.rows(), "layers": [{"choice": li.choice, "s": li.s, "gain": li.gain, "W_eff": np.asarray(li.W_eff).tolist(),
              "kurt": li.kurtosis} for li in ident.layers], "cands": [str(c) for c in ident.output_candidates]}
json.dump(out, open(sys.argv[1], "w"), indent=1, default=str)
