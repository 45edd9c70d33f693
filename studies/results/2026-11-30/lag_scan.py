"""Every lag row of the identification of every scored blind file (standing and time sets): its p,
Holm p and the classes named at 0.01 -- what a change to the lag test's p can move.
``python lag_scan.py FILES_DIR OUT.jsonl`` with PYTHONPATH at the code under test; resumable."""
import json, os, sys
from studies.blind_sets import SETS, _chosen
from gift_theory.lab import load_measurement, identify
root, path = sys.argv[1], sys.argv[2]
done = set()
if os.path.exists(path):
    done = {(r["set"], r["file"]) for r in map(json.loads, open(path))}
out = open(path, "a")
for s in SETS:
    folder = os.path.join(root, s)
    for _, f in _chosen(folder, s):
        if (s, f) in done:
            continue
        ident = identify(load_measurement(os.path.join(folder, f)))
        rows = ident.rows()
        lags = [{"layer": int(r["layer"]), "p": r["p"], "p_adj": r["p_adj"], "effect": r.get("effect")}
                for r in rows if r["test"] == "lag"]
        named = sorted({(r["class"], int(r["layer"])) for r in rows if r["p_adj"] < 0.01})
        row = {"set": s, "file": f, "lags": lags, "named": named, "min_p_adj": min(r["p_adj"] for r in rows)}
        out.write(json.dumps(row) + "\n"); out.flush()
        print(s, f, min((x["p"] for x in lags), default=None), file=sys.stderr, flush=True)
