"""Small correctly specified files (40 inputs x 8 shots, 6-12-4): how often does the diagnosis
explain them, and by what? Written for the rule *buys its keep where the identification looked*.

    python small_files.py OUT.jsonl [--seeds 5]

Each file: `gift simulate --arch 6-12-4 --inputs 40 --shots 8 --effect awgn=0.05 [--effect E]
--times [--taps] --seed S`, then `gift diagnose F --json --quiet --no-design`. The code is
whatever `gift` the PATH and PYTHONPATH give (a worktree on PYTHONPATH for "before"). Resumable:
rows already in OUT are skipped.
"""
import json
import os
import subprocess
import sys
import tempfile

EFFECTS = {"none": [], "shot": ["shot=0.02"], "multiplicative": ["multiplicative=0.3"],
           "common_mode": ["common_mode=0.3"], "laplace": ["laplace"]}


def main():
    out = sys.argv[1]
    seeds = int(sys.argv[sys.argv.index("--seeds") + 1]) if "--seeds" in sys.argv else 5
    done = set()
    if os.path.exists(out):
        for line in open(out):
            r = json.loads(line)
            done.add((r["effect"], r["taps"], r["seed"]))
    with tempfile.TemporaryDirectory() as tmp, open(out, "a") as f:
        for seed in range(seeds):
            for taps in (True, False):
                for name, eff in EFFECTS.items():
                    if (name, taps, seed) in done:
                        continue
                    path = os.path.join(tmp, f"{name}_{int(taps)}_{seed}.npz")
                    cmd = ["gift", "simulate", "--arch", "6-12-4", "--inputs", "40", "--shots", "8", "--effect",
                           "awgn=0.05"] + sum((["--effect", e] for e in eff), []) + \
                          ["--times", "--seed", str(seed), "--out", path, "--json"] + (["--taps"] if taps else [])
                    subprocess.run(cmd, check=True, capture_output=True)
                    p = subprocess.run(["gift", "diagnose", path, "--json", "--quiet", "--no-design"],
                                       capture_output=True, text=True)
                    d = json.loads(p.stdout)
                    top = d["ranking"][0] if d["ranking"] else {}
                    row = {"effect": name, "taps": taps, "seed": seed, "explained": d["explained"],
                           "top": "+".join(top.get("with", []) + [top.get("effect", "")]),
                           "bought": bool(top.get("bought_by")), "baseline_p": d["baseline"]["p_value"],
                           "missing": d["missing_effect_detected"], "verdict": d["verdict"]}
                    f.write(json.dumps(row) + "\n")
                    f.flush()
                    sys.stderr.write(f"{name} taps={taps} seed={seed}: {d['verdict'][:150]}\n")


if __name__ == "__main__":
    main()
