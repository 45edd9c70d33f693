"""A blind identification study: measurement files from an independent simulator.

    python -m studies.blind write DIR [--files-per-effect 3] [--seed 0] [--no-taps]
    python -m studies.blind score DIR [--limit N]

``write`` draws, per file, a random architecture (2-4 layers, widths 3-28, tanh), random
weights, inputs, noise level and effect strength, and simulates the chip with a plain-numpy
transcription of CONTRACTS §2 -- written from the contract's text, not from gift's forward
pass -- so the study sees what a user's own simulator (or the independent judge's) would
produce. Each file holds the CONTRACTS §3 keys plus ``hidden`` (the effects) and
``hidden_params`` for scoring; the loop never reads them. ``score`` runs
:func:`gift_theory.lab.diagnose` on every file and prints one JSON line per file and a
summary: detection rate (missing effect flagged), identification rate (hidden effect
ranked first; for two effects both among the top three names, or the top entry is the
pair), false alarms on files without a hidden effect, and the p-value after fitting the
winner.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from .contract_sim import loguniform, simulate_contract

#: effects of the study and the range each parameter is drawn from (log-uniform for scales)
EFFECTS = ("none", "laplace", "uniform", "multiplicative", "common_mode", "drift", "crosstalk", "weight_error",
           "shot", "saturation", "quantization", "shot+crosstalk", "multiplicative+common_mode")


def _draw_setting(rng, taps: bool):
    L = int(rng.integers(2, 5))
    widths = [int(rng.integers(3, 21))] + [int(rng.integers(6, 29)) for _ in range(L - 1)] + [int(rng.integers(2, 11))]
    gain = rng.uniform(0.8, 2.0)
    Ws = [rng.normal(0.0, gain / np.sqrt(widths[l]), (widths[l + 1], widths[l])) for l in range(L)]
    bs = [rng.normal(0.0, rng.uniform(0.0, 0.5), widths[l + 1]) for l in range(L)]
    n = int(rng.choice([120, 240]))
    r = int(rng.choice([32, 64]))
    kind = rng.integers(3)
    x = (rng.uniform(0, 1, (n, widths[0])) if kind == 0 else rng.uniform(-1, 1, (n, widths[0])) if kind == 1
         else rng.normal(0, 1, (n, widths[0])))
    s = loguniform(rng, 0.03, 0.15)
    return widths, Ws, bs, x, n, r, s


def _effect_params(rng, name, typical):
    """A visible but not overwhelming strength of ``name``; ``typical`` = rms of layer outputs."""
    if name == "multiplicative":
        return {"m": loguniform(rng, 0.1, 0.3)}
    if name == "common_mode":
        return {"c": loguniform(rng, 0.05, 0.2)}
    if name == "drift":
        return {"r": float(rng.choice([-1, 1]) * rng.uniform(0.15, 0.5))}
    if name == "crosstalk":
        return {"k": float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.3))}
    if name == "weight_error":
        return {"e": loguniform(rng, 0.05, 0.2)}
    if name == "shot":
        return {"q": loguniform(rng, 0.01, 0.05)}
    if name == "saturation":
        return {"v_max": float(typical * rng.uniform(0.8, 2.0))}
    if name == "quantization":
        return {"bits": float(rng.integers(4, 8)), "v_range": float(typical * rng.uniform(2.5, 5.0))}
    return {}


def write(folder, files_per_effect: int, seed: int, taps: bool, effects=EFFECTS):
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    written = []
    for name in effects:
        for i in range(files_per_effect):
            widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps)
            # the rms of the noiseless layer outputs sets saturation's and quantization's scale
            y0, tp0, _ = simulate_contract(np.random.default_rng(0), widths, Ws, bs, x, 2, 0.0, {})
            typical = float(np.sqrt(np.mean(np.concatenate([np.ravel(v) for v in tp0 + [y0]]) ** 2)))
            hidden = {} if name == "none" else {e: _effect_params(rng, e, typical) for e in name.split("+")}
            y, tp, t = simulate_contract(rng, widths, Ws, bs, x, r, s, hidden)
            arrays = {"x": x, "y": y, "t": t, "activation": np.array("tanh"),
                      "hidden": np.array(name), "hidden_params": np.array(json.dumps({"s": s, **hidden}))}
            for l, (W, b) in enumerate(zip(Ws, bs), start=1):
                arrays[f"W{l}"], arrays[f"b{l}"] = W, b
            if taps:
                for l, a in enumerate(tp, start=1):
                    arrays[f"a{l}"] = a
            path = os.path.join(folder, f"{name}_{i}.npz")
            np.savez(path, **arrays)
            written.append(path)
            sys.stderr.write(f"wrote {path}: arch {'-'.join(map(str, widths))}, n={n}, r={r}, s={s:.3g}, "
                             f"{json.dumps(hidden)}\n")
    return written


def score(folder, limit=None, out=sys.stdout):
    import jax

    from gift_theory.lab import diagnose, load_measurement

    files = sorted(f for f in os.listdir(folder) if f.endswith(".npz"))[:limit]
    rows = []
    for i, f in enumerate(files):
        path = os.path.join(folder, f)
        with np.load(path) as z:
            hidden = str(z["hidden"])
            truth = json.loads(str(z["hidden_params"]))
        meas = load_measurement(path)
        t0 = time.time()
        d = diagnose(jax.random.PRNGKey(i), meas)
        names = [c.effects[-1] for c in d.ranking]
        want = [] if hidden == "none" else hidden.split("+")
        top = names[:1] if len(want) < 2 else names[:3]
        first = list(d.ranking[0].effects)
        # two hidden effects: both among the top three names, or the top entry is exactly the pair
        ok = bool(want) and (all(h in top for h in want) or (len(want) > 1 and sorted(first) == sorted(want)))
        row = {"file": f, "hidden": hidden, "truth": truth, "arch": list(meas.arch.widths), "n": meas.n,
               "r": meas.r, "taps": meas.has_taps, "detected": d.missing_effect_detected,
               "baseline_p": d.baseline_comparison.p_value, "ranking": names[:4], "first_entry": first,
               "identified": ok,
               "p_after": d.ranking[0].comparison.p_value, "params_first": d.ranking[0].model.params_json(),
               "seconds": time.time() - t0}
        rows.append(row)
        out.write(json.dumps(row) + "\n")
        out.flush()
        sys.stderr.write(f"[{i + 1}/{len(files)}] {f}: detected {row['detected']} (p {row['baseline_p']:.2g}) "
                         f"first {names[0]} p_after {row['p_after']:.2g} ({row['seconds']:.0f} s)\n")
    summary = {"summary": True, "files": len(rows), "per_effect": {}}
    for name in sorted({r["hidden"] for r in rows}):
        rs = [r for r in rows if r["hidden"] == name]
        summary["per_effect"][name] = {
            "files": len(rs), "detected": int(sum(r["detected"] for r in rs)),
            "identified": int(sum(r["identified"] for r in rs)),
            "p_after_ok": int(sum(r["p_after"] >= 0.01 for r in rs))}
    eff = [r for r in rows if r["hidden"] != "none"]
    null = [r for r in rows if r["hidden"] == "none"]
    summary["identification_rate"] = float(np.mean([r["identified"] for r in eff])) if eff else None
    summary["detection_rate"] = float(np.mean([r["detected"] for r in eff])) if eff else None
    summary["false_alarm_rate"] = float(np.mean([r["detected"] for r in null])) if null else None
    out.write(json.dumps(summary) + "\n")
    return summary


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.blind", description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=("write", "score"))
    p.add_argument("folder")
    p.add_argument("--files-per-effect", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--taps", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--effects", default=",".join(EFFECTS))
    p.add_argument("--limit", type=int, default=None)
    a = p.parse_args(argv)
    if a.what == "write":
        write(a.folder, a.files_per_effect, a.seed, a.taps, tuple(a.effects.split(",")))
    else:
        score(a.folder, a.limit)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
