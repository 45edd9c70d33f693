import json, sys, math
def load(f):
    return {(r['s'], r['taps'], r['set']): r for r in map(json.loads, open(f))}
b, a = load(sys.argv[1]), load(sys.argv[2])
common = sorted(set(a) & set(b))
def alarm(r):
    return bool(r['ident_named_0.01']) or bool(r.get('failing_layers')) or r['baseline_p'] < 0.01
same = diff_alarm = 0; maxd = 0.0
from collections import Counter
ca, cb = Counter(), Counter()
for k in common:
    x, y = b[k], a[k]
    ca[k[:2]] += alarm(y); cb[k[:2]] += alarm(x)
    if alarm(x) != alarm(y): diff_alarm += 1; print('alarm differs', k, x['baseline_p'], y['baseline_p'], x['ident_named_0.01'], y['ident_named_0.01'], x['failing_layers'], y['failing_layers'])
    for f in ('baseline_p', 'fitted_s', 'ident_min_p_adj'):
        if x[f] != y[f]:
            d = abs(x[f] - y[f]) / max(abs(x[f]), 1e-300); maxd = max(maxd, d)
    if all(x.get(f) == y.get(f) for f in ('baseline_p','fitted_s','ident_min_p_adj','ident_named_0.01', 'one_step_p','layer_s','failing_layers')): same += 1
print(f'{len(common)} common rows, {same} identical in every field but seconds, {diff_alarm} alarms differ, max rel diff {maxd:.3g}')
for k in sorted(set(ca)|set(cb)): print(k, 'before', cb[k], 'after', ca[k], 'of', sum(1 for c in common if c[:2]==k))
