"""python jdiff.py DIR_A DIR_B: per JSON file in both, identical but for 'seconds'? else the first differing paths."""
import json, os, sys, glob
def diff(x, y, p, out):
    if isinstance(x, dict) and isinstance(y, dict):
        for k in sorted(set(x) | set(y)):
            if k in ("seconds", "study_seconds"): continue
            if k not in x or k not in y: out.append(p + "." + k + " (missing)"); continue
            diff(x[k], y[k], p + "." + k, out)
    elif isinstance(x, list) and isinstance(y, list):
        if len(x) != len(y): out.append(p + " (len)"); return
        for i, (u, v) in enumerate(zip(x, y)): diff(u, v, f"{p}[{i}]", out)
    elif x != y: out.append(f"{p}: {x!r} -> {y!r}")
a, b = sys.argv[1:3]
same = n = 0
for f in sorted(glob.glob(os.path.join(a, "**", "*.json"), recursive=True)):
    g = os.path.join(b, os.path.relpath(f, a))
    if not os.path.exists(g): continue
    n += 1; out = []
    diff(json.load(open(f)), json.load(open(g)), "", out)
    if not out: same += 1
    else: print(os.path.relpath(f, a), len(out), "; ".join(o[:140] for o in out[:4]))
print(f"{same}/{n} identical but for seconds")
