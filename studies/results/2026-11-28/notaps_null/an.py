import json, sys, numpy as np
for f in sys.argv[1:]:
    R = [json.loads(l) for l in open(f)]
    print(f, len(R))
    tests = sorted({(x["cls"], x["test"]) for q in R for x in q["rows"]})
    for t in tests:
        ps = np.array([x["p"] for q in R for x in q["rows"] if (x["cls"], x["test"]) == t])
        pa = np.array([x["p_adj"] for q in R for x in q["rows"] if (x["cls"], x["test"]) == t])
        zs = np.array([x["z"] if x["z"] is not None else np.nan for q in R for x in q["rows"] if (x["cls"], x["test"]) == t], float)
        print(f"  {t[0]+'/'+t[1]:40s} n={len(ps):3d} p<.01 {np.mean(ps<.01):.2f} p<.05 {np.mean(ps<.05):.2f} padj<.01 {np.mean(pa<.01):.2f}  (padj<.01 & z>4) {np.mean((pa<.01)&(zs>4)):.2f}")
    named = [q["seed"] for q in R if any(x["p_adj"] < 0.01 and not x["cls"].startswith("_") for x in q["rows"])]
    print("  files naming a class at padj .01:", len(named), named[:20])
