import json, glob, os, sys
def strip(d):
    if isinstance(d, dict): return {k: strip(v) for k, v in d.items() if 'seconds' not in k}
    if isinstance(d, list): return [strip(v) for v in d]
    return d
a, b = sys.argv[1], sys.argv[2]
n = same = 0
for f in sorted(glob.glob(os.path.join(a, 'json_*', '*.json'))):
    g = os.path.join(b, os.path.relpath(f, a))
    if not os.path.exists(g): continue
    n += 1
    if strip(json.load(open(f))) == strip(json.load(open(g))): same += 1
    else: print('DIFF', os.path.relpath(f, a))
print(f'{same}/{n} identical but for seconds')
