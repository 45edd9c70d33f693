"""The identification's rows on the null sets of studies.levels_null (same networks, inputs, draws).

    python ident_rows.py OUT.jsonl FIRST LAST S [yes|no]    # sets FIRST..LAST-1 at level S, taps (default yes)
    python ident_rows.py --summary OUT.jsonl [...]          # per test and layer: p < 0.01 / 0.05, classes named

Each row of OUT: the set, s, taps, every test's (class, test, layer, p, z, p_adj), seconds. Run
from the repository root with it on PYTHONPATH; appends (resumable by set ranges).
"""
import collections
import json
import sys
import time


def run(out, lo, hi, s, taps):
    import jax
    import numpy as np

    import gift_theory as gt
    from gift_theory.lab import identify, simulate_measurement
    from studies.calibrate import _network
    from studies.levels_null import INPUTS, SHOTS, WIDTHS

    with open(out, "a") as fh:
        for i in range(lo, hi):
            t0 = time.time()
            _, params = _network(1000 + i, WIDTHS)
            x = np.asarray(jax.random.uniform(jax.random.PRNGKey(2000 + i), (INPUTS, WIDTHS[0])))
            meas = simulate_measurement(jax.random.PRNGKey(3000 + i), params, x, gt.Physics.create(s=s), shots=SHOTS,
                                        taps=taps)
            rows = identify(meas).rows()
            keep = [{k: v for k, v in r.items() if k in ("class", "test", "p", "p_adj", "layer", "z")} for r in rows]
            fh.write(json.dumps({"set": i, "s": s, "taps": taps, "rows": keep, "sec": time.time() - t0}) + "\n")
            fh.flush()
            print(i, round(time.time() - t0, 1), file=sys.stderr, flush=True)


def summary(paths):
    from scipy import stats

    rows = [json.loads(line) for p in paths for line in open(p)]
    for key in sorted({(r["s"], r.get("taps", True)) for r in rows}):
        sel = [r for r in rows if (r["s"], r.get("taps", True)) == key]
        per, named = collections.defaultdict(list), collections.Counter()
        alarms = 0
        for r in sel:
            nm = {x["class"] for x in r["rows"] if x.get("p_adj", 1.0) < 0.01}
            alarms += bool(nm)
            named.update(nm)
            for x in r["rows"]:
                per[(x["class"], x["test"], x["layer"])].append(x["p"])
        b = stats.binomtest(alarms, len(sel), 0.01, alternative="greater").pvalue
        print(f"s = {key[0]:g}, taps {key[1]}: {len(sel)} sets, a class named at Holm 0.01 on {alarms} "
              f"(one-sided binomial p {b:.2g} against 1 %): {dict(named)}")
        for k, v in sorted(per.items()):
            print(f"    {k[0]:26s} {k[1]:16s} layer {k[2]}  n = {len(v):4d}  p < 0.01: {sum(p < 0.01 for p in v):3d}"
                  f"  p < 0.05: {sum(p < 0.05 for p in v):3d}")


if __name__ == "__main__":
    if sys.argv[1] == "--summary":
        summary(sys.argv[2:])
    else:
        run(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]),
            (sys.argv[5] != "no") if len(sys.argv) > 5 else True)
