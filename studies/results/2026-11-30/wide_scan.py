"""Which scored blind files reach the compiled wide smoothing rule (cells with noise sd > 0.5, at
least WIDE_CHUNK / 4 of them in one call -- the only cells 2f82a4a computes differently):
``python wide_scan.py FILES_DIR OUT.jsonl`` with PYTHONPATH at the code under test; files already
in OUT are skipped (a stopped scan resumes)."""
import json, os, sys
from studies.blind_sets import STANDING, _chosen
from gift_theory.lab import load_measurement, identify
import gift_theory.lab._smoothing as S
calls = []
orig = S._tanh_wide
def wide(z, sd):
    if z.size >= S.WIDE_CHUNK // 4:
        calls.append(int(z.size))
    return orig(z, sd)
S._tanh_wide = wide
root = sys.argv[1]
done = set()
if os.path.exists(sys.argv[2]):
    done = {(r["set"], r["file"]) for r in map(json.loads, open(sys.argv[2])) if r}
out = open(sys.argv[2], 'a')
for s in STANDING + ("time_nt", "time_t"):
    folder = os.path.join(root, s)
    for _, f in _chosen(folder, s):
        if (s, f) in done:
            continue
        calls.clear()
        identify(load_measurement(os.path.join(folder, f)))
        row = {"set": s, "file": f, "compiled_calls": len(calls), "cells": sum(calls)}
        out.write(json.dumps(row) + "\n"); out.flush()
        print(row, file=sys.stderr, flush=True)
