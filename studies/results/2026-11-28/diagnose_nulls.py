# Sixteen null chips (the 6-12-6-4 test chip of tests/lab/test_diagnose.py, seeds 20-27, 120 x 32, with and without taps) diagnosed
# end to end; run from the repository root (a snapshot of 37cba77 or later): python studies/results/2026-11-28/diagnose_nulls.py
import sys, jax, json, time
sys.path.insert(0, "tests/lab")
from test_diagnose import _chip
from gift_theory.lab import diagnose
for taps in (True, False):
    for seed in range(20, 28):
        t0 = time.time()
        meas = _chip({}, seed=seed, n=120, r=32, taps=taps)
        d = diagnose(jax.random.PRNGKey(seed), meas).as_json()
        r0 = d["ranking"][0] if d["ranking"] else {}
        print(json.dumps({"taps": taps, "seed": seed, "explained": d["explained"], "missing": d["missing_effect_detected"],
                          "verdict": d["verdict"][:120], "first": [*r0.get("with", []), r0.get("effect")], "status": r0.get("status"),
                          "pairs": sum(bool(r.get("with")) for r in d["ranking"]), "sec": round(time.time() - t0, 1)}), flush=True)
