"""Which files of the standing blind sets without taps have a noise-covariance test read at the
programmed map (the only path of the intersection-union change to ``_noise._noise_rows``): per
file the rows switched, with the fitted map's p and the one kept. ``python switch_scan.py
FILES_DIR OUT.jsonl SET[,SET...]`` with PYTHONPATH at the code under test; FILES_DIR holds the sets
written by ``python -m studies.blind_sets FILES_DIR --write-only``."""
import json, os, re, sys
from studies.blind_sets import _write, _chosen
from gift_theory.lab import load_measurement, identify
root, out = sys.argv[1], open(sys.argv[2], 'a')
for s in sys.argv[3].split(','):
    folder = os.path.join(root, s)
    _write(folder, s)
    for _, f in _chosen(folder, s):
        rows = identify(load_measurement(os.path.join(folder, f))).rows()
        sw = []
        for r in rows:
            m = re.search(r"read at the programmed map: the fitted one's p is ([0-9.e+-]+)\)", r["evidence"])
            if m:
                sw.append({"layer": int(r["layer"]), "test": r["test"], "p_fitted": float(m.group(1)), "p": r["p"],
                           "p_adj": r["p_adj"]})
        row = {'set': s, 'file': f, 'switched': sw, 'named': sorted({r['class'] for r in rows if r['p_adj'] < 0.01})}
        out.write(json.dumps(row) + '\n'); out.flush()
        print(row, file=sys.stderr, flush=True)
