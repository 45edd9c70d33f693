"""Coverage of the 95 % intervals of ``gift fit`` (reference §4 ``"intervals"``; issue 26 item 2).

    python -m studies.intervals [--files 100] [--cells s,q,kappa,sigma] [--taps both|yes|no]
                                [--out studies/results/2026-11-25d/intervals] [--report]

For each cell (a parameter, with or without taps) and file i, a chip is simulated by the
independent plain-numpy simulator (:mod:`studies.contract_sim`, written from reference §2, not
from gift's forward pass) with a true value drawn at random, on a random 6-10-8-3 tanh network
(60 inputs x 24 shots); gift fits the model exactly as ``gift fit FILE --add EFFECT`` does
(awgn on the fitting half, then the effect on top) and computes the interval of
:func:`gift_theory.lab.fit_uncertainty`. A row records the truth, the estimate, the
interval and whether it covers the truth.

    s      awgn only, s ~ U(0.03, 0.10)                          interval of s
    q      awgn (s ~ U(0.03, 0.08)) + shot, q ~ U(0.005, 0.03)    interval of q  (shot)
    kappa  awgn (s ~ U(0.03, 0.08)) + activation_gain, kappa ~ U(0.6, 1.6)
    sigma  awgn (s ~ U(0.03, 0.08)) + bias_offset, sigma ~ U(0.03, 0.15), a new device per file
           (its interval: the offsets' marginal-likelihood profile; the truth is the prior scale
           the device's offsets were drawn with, not their sample rms)

Resumable: rows go to ``OUT/<cell>.jsonl`` one JSON line each (file index, seed, truth, estimate,
interval, covered); a rerun skips the files already there. Cells are run round-robin (file 0 of
every cell, then file 1, ...), so a stopped run has every cell at about the same count.
Progress on stderr. ``--report`` (or the end of a run) writes ``OUT/summary.json`` and prints
the coverage table: per cell the count, the coverage and its binomial standard error
sqrt(p (1 - p) / n).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

WIDTHS = (6, 10, 8, 3)
N_INPUTS, SHOTS = 60, 24
#: cell -> (effect gift fits, the key of its interval in fit_uncertainty's answer)
CELLS = {"s": (None, "s"), "q": ("shot", "q"), "kappa": ("activation_gain", "kappa"),
         "sigma": ("bias_offset", "bias_offset")}
DEFAULT_OUT = os.path.join("studies", "results", "2026-11-25d", "intervals")


def _truth(cell: str, rng) -> tuple[float, dict, float]:
    """(s, contract_sim effects, the true value of the cell's parameter)."""
    from studies.contract_sim import bias_offset_device

    if cell == "s":
        s = float(rng.uniform(0.03, 0.10))
        return s, {}, s
    s = float(rng.uniform(0.03, 0.08))
    if cell == "q":
        q = float(rng.uniform(0.005, 0.03))
        return s, {"shot": {"q": q}}, q
    if cell == "kappa":
        k = float(rng.uniform(0.6, 1.6))
        return s, {"activation_gain": {"kappa": k}}, k
    sigma = float(rng.uniform(0.03, 0.15))
    return s, {"bias_offset": {"sigma": sigma, "delta": bias_offset_device(rng, WIDTHS, sigma)}}, sigma


def simulate(cell: str, seed: int, taps: bool):
    """One file of ``cell``: (Measurement, true value, true s)."""
    from gift_theory.lab import validate_arrays
    from studies.contract_sim import simulate_contract

    rng = np.random.default_rng([26, seed, list(CELLS).index(cell)])
    L = len(WIDTHS) - 1
    Ws = [rng.normal(0.0, 1.5 * math.sqrt(2.0 / (WIDTHS[l] + WIDTHS[l + 1])), (WIDTHS[l + 1], WIDTHS[l]))
          for l in range(L)]
    bs = [rng.uniform(-0.3, 0.3, WIDTHS[l + 1]) for l in range(L)]
    x = rng.uniform(0.0, 1.0, (N_INPUTS, WIDTHS[0]))
    s, effects, truth = _truth(cell, rng)
    y, tap_list, _ = simulate_contract(rng, WIDTHS, Ws, bs, x, SHOTS, s, effects)
    arrays = {"x": x, "y": y}
    for l in range(L):
        arrays[f"W{l + 1}"], arrays[f"b{l + 1}"] = Ws[l], bs[l]
    if taps:
        for l, a in enumerate(tap_list, start=1):
            arrays[f"a{l}"] = a
    return validate_arrays(arrays, where=f"{cell} file {seed}"), truth, s


def run_one(cell: str, seed: int, taps: bool) -> dict:
    """Fit one file as ``gift fit FILE --add EFFECT --seed SEED`` does and return its row."""
    import jax

    from gift_theory.lab import fit_model
    from gift_theory.lab import split_inputs
    from gift_theory.lab import fit_uncertainty
    from gift_theory.lab import MomentProblem

    t0 = time.time()
    meas, truth, s_true = simulate(cell, seed, taps)
    effect, name = CELLS[cell]
    key = jax.random.PRNGKey(seed)
    # fit_effects' fit without its held-out scoring: the same split, keys and model
    k_split, k_fit = jax.random.split(key, 5)[:2]
    train, _ = split_inputs(k_split, meas.n)
    fm = meas.subset(train)
    problem = MomentProblem(k_fit, fm, None)
    model = fit_model(k_fit, fm, (), problem=problem)
    if effect is not None:
        model = fit_model(k_fit, fm, (effect,), start=model, problem=problem, baseline=model)
    unc = fit_uncertainty(key, meas, model)
    params = model.params_json()
    lo, hi = unc["intervals"].get(name, [None, None])
    return {"cell": cell, "taps": taps, "seed": seed, "truth": truth, "s_true": s_true,
            "estimate": params.get(name), "interval": [lo, hi],
            "covered": None if lo is None else bool(lo <= truth <= hi),
            "s_interval": unc["intervals"].get("s"), "s_covered": bool(unc["intervals"]["s"][0] <= s_true
                                                                         <= unc["intervals"]["s"][1]),
            "seconds": time.time() - t0}


def _path(out, cell, taps):
    return os.path.join(out, f"{cell}_{'taps' if taps else 'notaps'}.jsonl")


def _rows(path):
    if not os.path.exists(path):
        return []
    rows = []
    with open(path) as fh:
        for line in fh:
            line = line.strip()
            if line:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:  # a line cut by a stop mid-write: that file reruns
                    pass
    return rows


def _unbounded(cell, interval) -> bool:
    """The interval is the parameter's whole range (the fit's loss is flat or concave there)."""
    from gift_theory.effects import REGISTRY

    lo, hi = (math.inf if v is None else float(v) for v in interval)
    effect, name = CELLS[cell]
    param = {"s": "s", "q": "q", "kappa": "kappa", "sigma": "sigma"}[cell]
    blo, bhi = REGISTRY[effect or "awgn"].bounds.get(param, (-math.inf, math.inf))
    return not math.isfinite(hi) or (lo <= blo and hi >= bhi)


def summary(out, cells, taps_list) -> dict:
    table = []
    for cell in cells:
        for taps in taps_list:
            every = _rows(_path(out, cell, taps))
            rows = [r for r in every if r.get("covered") is not None]
            n = len(rows)
            p = float(np.mean([r["covered"] for r in rows])) if n else float("nan")
            ps = float(np.mean([r["s_covered"] for r in rows])) if n else float("nan")
            # an interval as wide as the bounds covers by construction: counted apart
            unbounded = sum(1 for r in rows if _unbounded(cell, r["interval"]))
            table.append({"cell": cell, "taps": taps, "files": n, "failed": len(every) - n, "unbounded": unbounded,
                          "coverage": p,
                          "se": math.sqrt(p * (1 - p) / n) if n else float("nan"),
                          "coverage_s": ps, "se_s": math.sqrt(ps * (1 - ps) / n) if n else float("nan"),
                          "median_seconds": float(np.median([r["seconds"] for r in rows])) if n else float("nan")})
    return {"level": 0.95, "table": table}


def render(summ) -> str:
    lines = ["cell    taps   files  unbounded  coverage (95 % nominal)   coverage of s in the same fits"]
    for row in summ["table"]:
        lines.append(f"{row['cell']:<7s} {'yes' if row['taps'] else 'no':<5s} {row['files']:6d}  {row['unbounded']:9d}  "
                     f"{row['coverage']:.3f} +- {row['se']:.3f}            {row['coverage_s']:.3f} +- {row['se_s']:.3f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.intervals", description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=100, help="files per cell (default 100)")
    ap.add_argument("--cells", default=",".join(CELLS), help="comma-separated cells (default s,q,kappa,sigma)")
    ap.add_argument("--taps", choices=("both", "yes", "no"), default="both")
    ap.add_argument("--out", default=DEFAULT_OUT, help=f"results folder (default {DEFAULT_OUT})")
    ap.add_argument("--report", action="store_true", help="only write and print the summary of what is there")
    args = ap.parse_args(argv)
    cells = [c.strip() for c in args.cells.split(",") if c.strip()]
    bad = [c for c in cells if c not in CELLS]
    if bad:
        sys.stderr.write(f"--cells: unknown cell {bad[0]!r}; known: {', '.join(CELLS)}\n")
        return 2
    if args.files < 1:
        sys.stderr.write(f"--files {args.files}: needs at least 1\n")
        return 2
    taps_list = {"both": [True, False], "yes": [True], "no": [False]}[args.taps]
    os.makedirs(args.out, exist_ok=True)
    if not args.report:
        done = {(c, t): {r["seed"] for r in _rows(_path(args.out, c, t))} for c in cells for t in taps_list}
        total = len(cells) * len(taps_list) * args.files
        count = sum(len(v & set(range(args.files))) for v in done.values())
        t_start = time.time()
        for i in range(args.files):
            for cell in cells:
                for taps in taps_list:
                    if i in done[(cell, taps)]:
                        continue
                    try:
                        row = run_one(cell, i, taps)
                    except Exception as exc:  # a failed fit is a result too: kept, counted apart
                        row = {"cell": cell, "taps": taps, "seed": i, "truth": float("nan"), "covered": None,
                               "interval": [float("nan"), float("nan")], "seconds": 0.0,
                               "error": f"{type(exc).__name__}: {exc}"}
                    with open(_path(args.out, cell, taps), "a") as fh:  # one line per file: a stop loses one file
                        fh.write(json.dumps(row) + "\n")
                    count += 1
                    sys.stderr.write(f"[{count}/{total}] {cell} taps={taps} file {i}: truth {row['truth']:.4g} "
                                     f"interval [{row['interval'][0]:.4g}, {row['interval'][1]:.4g}] "
                                     f"{row.get('error') or ('covers' if row['covered'] else 'MISSES')} "
                                     f"({row['seconds']:.1f} s; "
                                     f"{time.time() - t_start:.0f} s so far)\n")
                    sys.stderr.flush()
    summ = summary(args.out, cells, taps_list)
    from gift_theory import atomic_write

    atomic_write(os.path.join(args.out, "summary.json"), lambda fh: fh.write(json.dumps(summ, indent=1).encode()))
    sys.stdout.write(render(summ) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
