"""python files_and_raw_p.py EFFECT SEEDS [--taps]   (env N inputs, default 40; R shots, default 8)

Simulates `gift simulate --arch 6-12-4 --inputs N --shots R --effect awgn=0.05 [--effect EFFECT]
--times [--taps] --seed S` for S < SEEDS into /tmp/cm/ (EFFECT "none": awgn alone; files already
there are reused), runs `identify` on each and prints, per time_drift test and layer, how many of
the raw p-values fall below 0.01 and 0.05."""
import contextlib
import io
import os
import sys

import numpy as np

from gift_theory.cli import main
from gift_theory.lab import identify, load_measurement

eff = sys.argv[1]; N = os.environ.get("N", "40"); R = os.environ.get("R", "8"); seeds = range(int(sys.argv[2]))
taps = "--taps" in sys.argv
os.makedirs("/tmp/cm", exist_ok=True)
out = []
for s in seeds:
    path = f"/tmp/cm/{N}x{R}_{eff.replace('=', '_')}_{int(taps)}_{s}.npz"
    if not os.path.exists(path):
        extra = [] if eff == "none" else ["--effect", eff]
        with contextlib.redirect_stdout(io.StringIO()):
            main(["simulate", "--arch", "6-12-4", "--inputs", N, "--shots", R, "--effect", "awgn=0.05", *extra,
                  "--times", "--seed", str(s), "--out", path, "--json"] + (["--taps"] if taps else []))
    rows = [r for r in identify(load_measurement(path)).rows() if r["class"] == "time_drift"]
    out.append({(r["test"], r["layer"]): r["p"] for r in rows})
for k in sorted({k for o in out for k in o}):
    ps = np.array([o.get(k, np.nan) for o in out])
    print(eff, "taps" if taps else "no taps", k, "files", int(np.sum(np.isfinite(ps))), "p<0.01:", int(np.sum(ps < 0.01)),
          "p<0.05:", int(np.sum(ps < 0.05)), "min %.2g" % np.nanmin(ps))
