"""Which files of the standing blind sets take a memory out (the only path 0dc3084 changes):
``python undo_scan.py FILES_DIR OUT.jsonl`` with PYTHONPATH at the code under test; FILES_DIR holds the
sets written by ``python -m studies.blind_sets FILES_DIR --write-only``."""
import glob, json, os, sys
import numpy as np
from studies.blind_sets import SETS, STANDING, _write, _chosen
from gift_theory.lab import load_measurement, identify
import gift_theory.lab._memory as M
calls = []
orig = M.undo
def undo(Y, lag):
    calls.append(lag.p); return orig(Y, lag)
M.undo = undo
root = sys.argv[1]
out = open(sys.argv[2], 'a')
for s in STANDING:
    folder = os.path.join(root, s)
    _write(folder, s)
    for _, f in _chosen(folder, s):
        f = os.path.join(folder, f)
        calls.clear()
        meas = load_measurement(f)
        ident = identify(meas)
        lags = [r['p'] for r in ident.rows() if r['test'] == 'lag']
        row = {'set': s, 'file': os.path.basename(f), 'min_lag_p': min(lags) if lags else None, 'undone': len(calls)}
        out.write(json.dumps(row) + '\n'); out.flush()
        print(row, file=sys.stderr, flush=True)
