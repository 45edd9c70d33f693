"""Diff of gift diagnose --json between two output folders: verdict, explained, classes ranked,
statuses, p-values (exact, else the largest relative difference), and any other field."""
import json, sys, os, math
A, B = sys.argv[1], sys.argv[2]
def flat(x, pre=""):
    if isinstance(x, dict):
        for k, v in x.items(): yield from flat(v, f"{pre}.{k}")
    elif isinstance(x, list):
        for i, v in enumerate(x): yield from flat(v, f"{pre}[{i}]")
    else: yield pre, x
for f in sorted(os.listdir(A)):
    if not f.endswith(".json"): continue
    a, b = json.load(open(os.path.join(A, f))), json.load(open(os.path.join(B, f)))
    fa, fb = dict(flat(a)), dict(flat(b))
    fa.pop(".seconds", None); fb.pop(".seconds", None)
    diffs = [(k, fa.get(k), fb.get(k)) for k in sorted(set(fa) | set(fb)) if fa.get(k) != fb.get(k)]
    num = [(k, x, y) for k, x, y in diffs if isinstance(x, float) and isinstance(y, float)]
    other = [(k, x, y) for k, x, y in diffs if (k, x, y) not in num]
    rel = max((abs(x - y) / max(abs(x), abs(y), 1e-300) for k, x, y in num), default=0.0)
    same_v = a["verdict"] == b["verdict"] and a["explained"] == b["explained"]
    ranks = ([r["effect"] + "/" + r["status"] for r in a["ranking"]] == [r["effect"] + "/" + r["status"] for r in b["ranking"]])
    print(f"{f}: verdict same {same_v}, ranking same {ranks}, fields differing {len(diffs)} "
          f"(numeric {len(num)}, max rel {rel:.2g}; other {len(other)})")
    for k, x, y in other[:5]: print("   ", k, repr(x)[:100], "->", repr(y)[:100])
    for k, x, y in sorted(num, key=lambda t: -abs(t[1]-t[2])/max(abs(t[1]),abs(t[2]),1e-300))[:3]: print("   ", k, x, "->", y)
