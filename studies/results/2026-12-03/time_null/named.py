"""python named.py 'GLOB'  -- per file set: the classes the identification names (Holm-adjusted
0.01, as the verdict reads them) and, per time_drift test and layer, how many adjusted p < 0.01."""
import collections
import glob
import sys

import numpy as np

from gift_theory.lab import identify, load_measurement
from gift_theory.lab._mechanisms import named

files = sorted(glob.glob(sys.argv[1]))
cnt = collections.Counter()
adj = collections.defaultdict(list)
for f in files:
    ident = identify(load_measurement(f))
    rows = ident.rows()
    for r in rows:
        if r["class"] == "time_drift":
            adj[(r["test"], r["layer"])].append(r.get("p_adj", np.nan))
    cnt[tuple(sorted({r["class"] for r in rows if named(r, ident.taps)}))] += 1
print(len(files), "files; classes named:", dict(cnt))
for k, v in sorted(adj.items()):
    v = np.array(v)
    print(k, "p_adj < 0.01:", int(np.sum(v < 0.01)), "min %.2g" % np.nanmin(v))
