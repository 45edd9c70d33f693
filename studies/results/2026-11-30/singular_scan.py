"""Which files of the standing blind sets reach the identification's pseudo-inverse -- a design
the data see only in part, or a covariance singular to rounding (the only paths the change to
``_stats._gram_inv`` / ``_psd_solve`` alters): ``python singular_scan.py FILES_DIR OUT.jsonl``
with PYTHONPATH at the code under test; FILES_DIR holds the sets written by
``python -m studies.blind_sets FILES_DIR --write-only``."""
import json, os, sys
import numpy as np
from studies.blind_sets import STANDING, _write, _chosen
from gift_theory.lab import load_measurement, identify
import gift_theory.lab.identification._stats as S
import gift_theory.lab.identification._map_rows as R
seen = {"unseen": 0, "zero_inputs_only": 0, "truncated": 0}
g_orig, t_orig = S._gram_inv, S._truncated
def gram_inv(G):
    Binv, unseen = g_orig(G)
    for i, (mask, proj) in unseen.items():
        zero = np.diag(G[i]) <= 0
        seen["zero_inputs_only" if np.array_equal(mask, zero) else "unseen"] += 1
    return Binv, unseen
def truncated(Ss):
    seen["truncated"] += 1
    return t_orig(Ss)
S._gram_inv = R._gram_inv = gram_inv
S._truncated = truncated
root = sys.argv[1]
out = open(sys.argv[2], 'a')
for s in STANDING:
    folder = os.path.join(root, s)
    _write(folder, s)
    for _, f in _chosen(folder, s):
        f = os.path.join(folder, f)
        for k in seen:
            seen[k] = 0
        ident = identify(load_measurement(f))
        row = {'set': s, 'file': os.path.basename(f), **seen}
        out.write(json.dumps(row) + '\n'); out.flush()
        print(row, file=sys.stderr, flush=True)
