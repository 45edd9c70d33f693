# aggregate a py-spy raw profile: inclusive seconds per function (25 Hz); argv[2] filters names
import sys, collections, re
inc=collections.Counter(); tot=0
for line in open(sys.argv[1], errors="replace"):
    line=line.rstrip()
    parts = line.rsplit(' ',1)
    if len(parts) != 2 or not parts[1].isdigit(): continue
    stack, n = parts[0], int(parts[1]); tot+=n
    seen=set()
    for f in stack.split(';'):
        if f.startswith('process '): continue
        key=re.sub(r':\d+\)$',')',f)
        if key not in seen:
            inc[key]+=n; seen.add(key)
pat=sys.argv[2] if len(sys.argv)>2 else ''
print('total',tot)
for k,v in inc.most_common(3000):
    if pat in k: print(f"{v/tot*100:6.2f}% {v/25:8.1f}s {k}")
