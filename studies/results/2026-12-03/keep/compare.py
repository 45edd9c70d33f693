"""Before/after table of small_files.py's rows: python compare.py BEFORE.jsonl AFTER.jsonl"""
import json
import sys

CLASS = {"shot": "input_dependent_noise", "multiplicative": "input_dependent_noise", "common_mode": "gain_fluctuation",
         "laplace": "noise_law", "uniform": "noise_law", "none": "none", "awgn": "none"}


def classes(name):
    return {CLASS.get(e, e) for e in name.split("+")}


B = {(r["effect"], r["taps"], r["seed"]): r for r in map(json.loads, open(sys.argv[1]))}
A = {(r["effect"], r["taps"], r["seed"]): r for r in map(json.loads, open(sys.argv[2]))}
keys = sorted(set(A) & set(B))
for k in keys:
    b, a = B[k], A[k]
    if (b["explained"], b["top"]) != (a["explained"], a["top"]):
        print(f"{k[0]:<15s} taps={k[1]!s:<5s} seed {k[2]}: {'explained' if b['explained'] else 'NOT explained'} "
              f"({b['top']}) -> {'explained' if a['explained'] else 'NOT explained'} ({a['top']})"
              + (" [bought where the identification looked]" if a["bought"] else ""))
print("| taps | effect | files | explained before -> after | by its own class before -> after |")
print("|---|---|---|---|---|")
for taps in (True, False):
    for eff in sorted({k[0] for k in keys}):
        ks = [k for k in keys if k[1] == taps and k[0] == eff]
        def count(D, right):
            return sum(D[k]["explained"] and (not right or classes(D[k]["top"]) == classes(eff)) for k in ks)
        print(f"| {'yes' if taps else 'no'} | {eff} | {len(ks)} | {count(B, False)} -> {count(A, False)} | "
              f"{count(B, True)} -> {count(A, True)} |")
