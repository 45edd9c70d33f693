import re, sys, collections
inc = collections.Counter(); self_ = collections.Counter(); total = 0
tests = collections.Counter()
for line in open(sys.argv[1]):
    line = line.rstrip()
    stack, _, n = line.rpartition(' ')
    try: n = int(n)
    except ValueError: continue
    total += n
    frames = stack.split(';')
    keys = []
    for f in frames:
        m = re.match(r'(.*?) \((.*?)(?::\d+)?\)$', f)
        k = (m.group(1) + ' ' + m.group(2).split('site-packages/')[-1].replace('/work/main/','')) if m else f
        keys.append(k)
    for k in set(keys): inc[k] += n
    self_[keys[-1]] += n
    t = [k for k in keys if k.startswith('test_')]
    tests[t[0] if t else '(none)'] += n
print('total samples', total, '=', total/20, 's')
pat = sys.argv[2] if len(sys.argv) > 2 else ''
for k, v in inc.most_common(400):
    if pat in k: print(f'{v/20:8.1f} {100*v/total:5.1f}%  {k}')
