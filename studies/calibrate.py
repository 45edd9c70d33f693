"""Statistical calibration of the measurement loop (a script, not a test: it takes minutes).

    python -m studies.calibrate null  [--sets 120] [--taps|--no-taps] [--fitted [--effect NAME]]
    python -m studies.calibrate ident-null [--sets 120] [--taps|--no-taps]
    python -m studies.calibrate ident [--seeds 3] [--taps|--no-taps] [--effects a,b]
    python -m studies.calibrate time  [--taps] [--warm N] [--fresh N]

``null``: data sets simulated from the awgn model itself; the share of p < 0.01 (and
< 0.05) is the false-alarm rate of the goodness-of-fit test. With ``--fitted`` the model's
s is fitted on half the inputs and the p-value taken on the other half, exactly as
``gift diagnose`` does (the realistic case); without, the true model is scored. With
``--fitted --effect NAME`` the data have the hidden effect NAME and the model fits it too
(the p-value after ``fit --add NAME`` when NAME is the right answer; weight_error: with its
refit null); for an effect fitted as offsets each row also says which checks of the fitted
values refused them (``prior_refused``: the verdict's rule b, so a refusal here is a false
one) and the coupling test's p per layer, and the summary the refusal rate.

``ident-null``: the layer-wise identification alone on the null files of ``null`` (the same
networks, inputs and draws): how often it names a class at Holm-adjusted 0.01 and 0.05, and
per test and layer its unadjusted rejection rates and a KS p-value against the uniform law.

``ident``: for every effect of reference §2 (and a two-effect case and the null), data
with that hidden effect on a random network per seed; records whether ``diagnose`` flags a
missing effect, ranks the hidden one first (top three for two), and whether the winner's
p-value after fitting is >= 0.01. ``time``: one ``diagnose`` of a 240-input x 64-shot file
on a 16-32-16-8 network; ``--fresh N`` runs it in N fresh processes one after the other (the
second and later load the compiled programs from the disk cache: the time a user sees on a
second ``gift diagnose``), each with its CPU seconds and the load average.

Every row is printed as one JSON line on stdout (progress on stderr), so a partial run is
still a result; the summary is the last line.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax
import numpy as np

#: hidden effects of the identification study (strong enough to be seen at this size)
HIDDEN = {
    "laplace": {"laplace": True},
    "uniform": {"uniform": True},
    "multiplicative": {"multiplicative": 0.2},
    "common_mode": {"common_mode": 0.2},
    "drift": {"drift": 0.4},
    "crosstalk": {"crosstalk": 0.2},
    "weight_error": {"weight_error": {"e": 0.15}},
    "shot": {"shot": 0.03},
    "saturation": {"saturation": 0.7},
    "quantization": {"quantization": {"bits": 5, "v_range": 2.0}},
    "layer_gain": {"layer_gain": {"g": ((0.6,), (0.8,), (1.25,))}},
    "shot+crosstalk": {"shot": 0.03, "crosstalk": 0.2},
    "none": {},
}


def _network(seed, widths, activation="tanh"):
    import gift_theory as gt

    arch = gt.Architecture(widths, activation)
    key = jax.random.PRNGKey(seed)
    params = gt.init_params(jax.random.fold_in(key, 1), arch, gain=1.5)
    # non-zero biases: the tanh works at several operating points
    params = tuple(gt.Layer(W, 0.3 * jax.random.normal(jax.random.fold_in(key, 10 + l), b.shape))
                   for l, (W, b) in enumerate(params))
    return arch, params


def _physics(spec, s, seed):
    import gift_theory as gt

    spec = {k: (dict(v, seed=seed) if k == "weight_error" else v) for k, v in spec.items()}
    return gt.Physics.create(s=s, **spec)


def null_study(sets, widths, n, r, s, taps, fitted, out, effect=None):
    import gift_theory as gt
    from gift_theory.lab import Model, compare, simulate_measurement
    from gift_theory.lab import Session
    from gift_theory.lab import prior_check, refusing

    from gift_theory.lab import identify

    ps, refused, ident_p = [], [], []
    t0 = time.time()
    for i in range(sets):
        arch, params = _network(1000 + i, widths)
        x = np.asarray(jax.random.uniform(jax.random.PRNGKey(2000 + i), (n, widths[0])))
        phys = gt.Physics.create(s=s) if effect is None else _physics(HIDDEN[effect], s, 5000 + i)
        meas = simulate_measurement(jax.random.PRNGKey(3000 + i), params, x, phys, shots=r, taps=taps,
                                    times=effect == "drift")
        key = jax.random.PRNGKey(4000 + i)
        prior = None
        if fitted:  # exactly as diagnose scores a candidate
            session = Session(key, meas)
            model = None if effect is None else session.fit(tuple(HIDDEN[effect]), start=session.baseline)
            c = session.baseline_comparison if effect is None else session.score(model)
            if model is not None and model.offsets:  # the verdict's check of the fitted values (rule b)
                prior = prior_check(model, session.fit_meas)
            if effect is None:  # the identification's smallest Holm-adjusted p over every class and layer
                rows = identify(meas).rows()
                ident_p.append(min((r.get("p_adj", 1.0) for r in rows), default=1.0))
                flagged = sorted({r["class"] for r in rows if r.get("p_adj", 1.0) < 0.05})
        else:
            c = compare(key, Model(phys), meas)
        ps.append(c.p_value)
        row = {"study": "null", "set": i, "p_value": c.p_value, "discrepancy": c.discrepancy, "se": c.se,
               "noise_floor": c.noise_floor, "taps": taps, "fitted": fitted, "effect": effect}
        if ident_p and effect is None and fitted:
            row["identify_min_p_adj"], row["identify_flagged_0.05"] = ident_p[-1], flagged
        if prior is not None:
            row["prior_refused"] = [f"{r['test']}@{r['layer']}" for r in refusing(prior)]
            row["coupling_p"] = [r["p"] for r in prior if r["test"] == "w_coupling"]
            refused.append(bool(row["prior_refused"]))
        out.write(json.dumps(row) + "\n")
        out.flush()
        if (i + 1) % 10 == 0:
            sys.stderr.write(f"null {i + 1}/{sets}: false alarms at 0.01 so far {np.mean(np.array(ps) < 0.01):.3f} "
                             f"({time.time() - t0:.0f} s)\n")
    ps = np.array(ps)
    from scipy import stats
    return {"study": "null", "summary": True, "sets": sets, "taps": taps, "fitted": fitted, "effect": effect,
            "arch": list(widths), "inputs": n, "shots": r, "s": s,
            "false_alarm_rate_0.01": float(np.mean(ps < 0.01)), "false_alarm_rate_0.05": float(np.mean(ps < 0.05)),
            "ks_uniform_p": float(stats.kstest(ps, "uniform").pvalue),
            # fitted offsets of the true effect refused as not its own (the verdict's rule b): a false refusal
            **({"prior_refusal_rate": float(np.mean(refused))} if refused else {}),
            # the identification names a class on null data (any test, Holm-adjusted over classes x layers)
            **({"identify_flag_rate_0.01": float(np.mean(np.array(ident_p) < 0.01)),
                "identify_flag_rate_0.05": float(np.mean(np.array(ident_p) < 0.05))} if ident_p else {}),
            "seconds": time.time() - t0}


def ident_null_study(sets, widths, n, r, s, taps, out):
    """The identification alone on null files (awgn only; the same networks, inputs and draws as
    :func:`null_study`): per file the smallest Holm-adjusted p and the classes named at 0.05;
    the summary has the family-wise rates and, per test and layer, its unadjusted rejection
    rates and a KS p of its p-values against the uniform law."""
    import gift_theory as gt
    from gift_theory.lab import identify, simulate_measurement
    from scipy import stats

    ident_p, per_test = [], {}
    t0 = time.time()
    for i in range(sets):
        arch, params = _network(1000 + i, widths)
        x = np.asarray(jax.random.uniform(jax.random.PRNGKey(2000 + i), (n, widths[0])))
        meas = simulate_measurement(jax.random.PRNGKey(3000 + i), params, x, gt.Physics.create(s=s), shots=r,
                                    taps=taps)
        rows = identify(meas).rows()
        ident_p.append(min((rw["p_adj"] for rw in rows), default=1.0))
        for rw in rows:
            per_test.setdefault(f"{rw['class']}/{rw['test']}@{rw['layer']}", []).append(rw["p"])
        out.write(json.dumps({"study": "ident-null", "set": i, "taps": taps, "identify_min_p_adj": ident_p[-1],
                              "identify_flagged_0.05": sorted({rw["class"] for rw in rows if rw["p_adj"] < 0.05}),
                              "p": {f"{rw['class']}/{rw['test']}@{rw['layer']}": rw["p"] for rw in rows}}) + "\n")
        out.flush()
        if (i + 1) % 20 == 0:
            sys.stderr.write(f"ident-null {i + 1}/{sets}: a class named at 0.01 on "
                             f"{np.mean(np.array(ident_p) < 0.01):.3f} of files ({time.time() - t0:.0f} s)\n")
    ip = np.array(ident_p)
    tests = {k: {"files": len(v), "rate_0.01": float(np.mean(np.array(v) < 0.01)),
                 "rate_0.05": float(np.mean(np.array(v) < 0.05)),
                 "ks_uniform_p": float(stats.kstest(v, "uniform").pvalue) if len(v) > 1 else None}
             for k, v in sorted(per_test.items())}
    return {"study": "ident-null", "summary": True, "sets": sets, "taps": taps, "arch": list(widths), "inputs": n,
            "shots": r, "s": s, "identify_flag_rate_0.01": float(np.mean(ip < 0.01)),
            "identify_flag_rate_0.05": float(np.mean(ip < 0.05)), "tests": tests, "seconds": time.time() - t0}


def ident_study(seeds, widths, n, r, s, taps, effects, out):
    from gift_theory.lab import diagnose, simulate_measurement

    rows = []
    for name in effects:
        spec = HIDDEN[name]
        hidden = [e for e in spec]
        for seed in range(seeds):
            arch, params = _network(seed, widths)
            x = np.asarray(jax.random.uniform(jax.random.PRNGKey(500 + seed), (n, widths[0])))
            phys = _physics(spec, s, 77 + seed)
            meas = simulate_measurement(jax.random.PRNGKey(600 + seed), params, x, phys, shots=r, taps=taps, times=True)
            t0 = time.time()
            d = diagnose(jax.random.PRNGKey(700 + seed), meas)
            names = [c.effects[-1] for c in d.ranking]
            k = max(len(hidden), 1) if len(hidden) < 2 else 3
            top = names[:k]
            row = {"study": "ident", "hidden": name, "seed": seed, "taps": taps,
                   "detected": d.missing_effect_detected, "baseline_p": d.baseline_comparison.p_value,
                   "ranking": names[:4], "identified": bool(hidden) and all(h in top for h in hidden),
                   "first": names[0], "p_after": d.ranking[0].comparison.p_value,
                   "params_first": d.ranking[0].model.params_json(), "seconds": time.time() - t0}
            rows.append(row)
            out.write(json.dumps(row) + "\n")
            out.flush()
            sys.stderr.write(f"{name:15s} seed {seed}: detected {row['detected']} first {names[0]} "
                             f"p_after {row['p_after']:.3g} ({row['seconds']:.0f} s)\n")
    summary = {"study": "ident", "summary": True, "taps": taps, "seeds": seeds, "arch": list(widths),
               "inputs": n, "shots": r, "s": s, "per_effect": {}}
    for name in effects:
        rs = [x for x in rows if x["hidden"] == name]
        summary["per_effect"][name] = {
            "detected_rate": float(np.mean([x["detected"] for x in rs])),
            "identified_rate": float(np.mean([x["identified"] for x in rs])) if name != "none" else None,
            "identified_given_detected": (float(np.mean([x["identified"] for x in rs if x["detected"]]))
                                          if name != "none" and any(x["detected"] for x in rs) else None),
            "p_after_ok_rate": float(np.mean([x["p_after"] >= 0.01 for x in rs]))}
    return summary


def time_fresh(taps, fresh: int, out):
    """``fresh`` fresh processes one after the other, each one ``time`` study with no warm call
    (its first call: in the second and later processes the compiled programs come from the disk
    cache); per process its wall and CPU seconds of the diagnose and the 1-minute load average
    before it (the machine may be shared: compare paired runs)."""
    import os
    import subprocess

    rows = []
    for i in range(int(fresh)):
        load = os.getloadavg()[0]
        args = [sys.executable, "-c", "import sys, json; from studies.calibrate import time_study; "
                f"print(json.dumps(time_study({bool(taps)}, sys.stdout, warm=0)))"]
        done = subprocess.run(args, capture_output=True, text=True, check=True)
        row = json.loads(done.stdout.strip().splitlines()[-1])
        row.update({"study": "time_fresh", "process": i + 1, "load_average_1min": load})
        rows.append(row)
        out.write(json.dumps(row) + "\n")
        out.flush()
        print(f"[time] fresh process {i + 1}: {row['seconds_first_call']:.2f} s (cpu {row['cpu_first_call']:.2f} s, "
              f"load {load:.1f})", file=sys.stderr)
    later = [r["seconds_first_call"] for r in rows[1:]]
    return {"study": "time", "summary": True, "taps": taps, "fresh": int(fresh),
            "seconds_fresh": [r["seconds_first_call"] for r in rows],
            "cpu_fresh": [r["cpu_first_call"] for r in rows],
            "load_average_1min": [r["load_average_1min"] for r in rows],
            **({"seconds_second_and_later_median": float(np.median(later))} if later else {})}


def time_study(taps, out, warm: int = 1):
    """One diagnose in a fresh process (key 3: compiles, or loads from the disk cache), then
    ``warm`` more in the same process (keys 4, 5, ...). ``seconds_compiled`` is key 4's, the
    slow path of this file: its split makes awgn + shot, the true model, fail at p = 0.0063, so
    that call also runs the second stage and traces its programs; other keys show the common
    path (``explained`` per call says which)."""
    import gift_theory as gt
    from gift_theory.lab import diagnose, simulate_measurement

    widths = (16, 32, 16, 8)
    arch, params = _network(0, widths)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (240, 16)))
    meas = simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1, shot=0.02), shots=64,
                                taps=taps, times=True)
    t0, c0 = time.time(), os.times()
    diagnose(jax.random.PRNGKey(3), meas)
    first, c1 = time.time() - t0, os.times()
    cpu_first = c1.user + c1.system - c0.user - c0.system
    if warm == 0:
        return {"study": "time", "summary": True, "taps": taps, "arch": list(widths), "inputs": 240, "shots": 64,
                "seconds_first_call": first, "cpu_first_call": cpu_first}
    seconds, explained = [], []
    for k in range(4, 4 + int(warm)):
        t0 = time.time()
        d = diagnose(jax.random.PRNGKey(k), meas)
        seconds.append(time.time() - t0)
        explained.append(bool(d.explained))
        print(f"[time] warm call, key {k}: {seconds[-1]:.2f} s (explained: {explained[-1]})", file=sys.stderr)
    res = {"study": "time", "summary": True, "taps": taps, "arch": list(widths), "inputs": 240, "shots": 64,
           "seconds_first_call": first, "cpu_first_call": cpu_first, "seconds_compiled": seconds[0]}
    if len(seconds) > 1:
        res.update({"seconds_warm": seconds, "explained_warm": explained,
                    "seconds_warm_median": float(np.median(seconds))})
    return res


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.calibrate", description=__doc__.split("\n\n")[0])
    p.add_argument("study", choices=("null", "ident-null", "ident", "time"))
    p.add_argument("--sets", type=int, default=120)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--taps", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--fitted", action="store_true")
    p.add_argument("--arch", default="12-24-12-6")
    p.add_argument("--inputs", type=int, default=160)
    p.add_argument("--shots", type=int, default=48)
    p.add_argument("--warm", type=int, default=1, help="time: diagnose calls after the first (keys 4, 5, ...)")
    p.add_argument("--fresh", type=int, default=0,
                   help="time: instead, N fresh processes one after the other, each timing its first call")
    p.add_argument("--s", type=float, default=0.1)
    p.add_argument("--effects", default=",".join(HIDDEN))
    p.add_argument("--effect", default=None, choices=[k for k in HIDDEN if "+" not in k and k != "none"],
                   help="null: the data have this hidden effect and the model fits it (with --fitted)")
    a = p.parse_args(argv)
    if a.warm < 1:
        p.error(f"--warm {a.warm}: the time study makes at least one warm call")
    widths = tuple(int(w) for w in a.arch.split("-"))
    out = sys.stdout
    if a.study == "null":
        if a.effect is not None and not a.fitted:
            p.error("--effect needs --fitted (the model fits the effect's parameters)")
        res = null_study(a.sets, widths, a.inputs, a.shots, a.s, a.taps, a.fitted, out, a.effect)
    elif a.study == "ident-null":
        res = ident_null_study(a.sets, widths, a.inputs, a.shots, a.s, a.taps, out)
    elif a.study == "ident":
        res = ident_study(a.seeds, widths, a.inputs, a.shots, a.s, a.taps, a.effects.split(","), out)
    elif a.fresh:
        if a.fresh < 0:
            p.error(f"--fresh {a.fresh}: the number of processes must be at least 1")
        res = time_fresh(a.taps, a.fresh, out)
    else:
        res = time_study(a.taps, out, a.warm)
    out.write(json.dumps(res) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
