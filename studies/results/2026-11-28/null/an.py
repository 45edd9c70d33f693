import json, sys, numpy as np
from scipy import stats
for f in sys.argv[1:]:
    R = [json.loads(l) for l in open(f)]
    zu = np.array([r["zu"] for r in R if r["zu"] is not None and np.isfinite(r["zu"])])
    z1 = np.array([r["z1"] for r in R])
    p = np.array([r["p"] for r in R]); pa = np.array([r["p_adj"] for r in R])
    print(f"{f}: rows {len(R)}  zu n={zu.size} mean {zu.mean():+.2f} sd {zu.std():.2f} min {zu.min():.1f} max {zu.max():.1f} "
          f"frac zu>2.33 {np.mean(zu>2.33):.3f}  z1 mean {z1.mean():+.2f} sd {z1.std():.2f}  p<.01 {np.mean(p<.01):.3f} padj<.01 {np.mean(pa<.01):.3f}")
