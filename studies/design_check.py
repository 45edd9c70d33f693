"""Does the advised next measurement resolve an ambiguity? (issue 48's validation of ``gift design``)

    python -m studies.design_check OUT.jsonl --scenario shot_vs_mult --chips 12 [--first 0]
    python -m studies.design_check OUT.jsonl --summary

Per chip (a random small tanh network and its true physics, simulated by the plain-numpy
:mod:`studies.contract_sim`, never by gift's forward pass): campaign 1 is diagnosed as
``gift diagnose`` does (:func:`gift_theory.lab.diagnose`, the next measurement designed). When the
data cannot choose (``explained_by`` holds two or more models), two more campaigns are simulated on
the same chip -- the advised one (its inputs, shots, taps, order) and, as a yardstick, one of the
same size with the first design (the same inputs, as many shots in all, fresh noise). On each,
the advised statistic decides (:func:`gift_theory.lab._design.decide`: the hypotheses as fitted on
campaign 1, each rejected at 0.01 or not): the campaign *decides* when exactly one hypothesis is
left, *right* when it is of the chip's true class. Each is also diagnosed on its own, and the
diagnosis counted when it is explained by one model (of the true class). One JSON line
per chip (resumable: chips already in OUT are skipped); ``--summary`` tables the share of
ambiguous chips resolved (right) by each campaign and the shots each took.

Scenarios (``SCENARIOS``): ``shot_vs_mult`` -- shot noise at every readout (q), seen without taps,
where a per-neuron multiplicative gain noise can pass as well; ``kappa_vs_gain`` -- an activation
slope kappa on the hidden layers with small biases, seen without taps, where a gain on each layer's
weighted sum does nearly the same; ``saturation`` -- a mild compression of every readout (v_max
1.5-3 times the output's rms), seen without taps, where an activation's slope or a gain can pass
as well.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

SCENARIOS = {
    "shot_vs_mult": {"class": "input_dependent_noise", "truth": "shot"},
    "kappa_vs_gain": {"class": "activation_mismatch", "truth": "activation_gain"},
    "saturation": {"class": "readout_nonlinearity", "truth": "saturation"},
}


def _chip(scenario: str, i: int, seed: int):
    rng = np.random.default_rng([seed, 48, i, len(scenario)])
    L = 2
    widths = [int(rng.integers(3, 7)), int(rng.integers(6, 12)), int(rng.integers(2, 5))]
    gain = rng.uniform(1.0, 2.0)
    Ws = [rng.normal(0.0, gain / np.sqrt(widths[l]), (widths[l + 1], widths[l])) for l in range(L)]
    if scenario == "kappa_vs_gain":
        bs = [rng.normal(0.0, 0.05, widths[l + 1]) for l in range(L)]
        effects = {"activation_gain": {"kappa": float(1.0 + rng.choice([-1, 1]) * rng.uniform(0.1, 0.2))}}
    elif scenario == "saturation":
        bs = [rng.normal(0.0, 0.3, widths[l + 1]) for l in range(L)]
        # a mild compression: v_max 1.5-3 times the output's rms (the study's inputs, noiseless)
        x0 = rng.uniform(-1.0, 1.0, (200, widths[0]))
        out = np.tanh(x0 @ Ws[0].T + bs[0]) @ Ws[1].T + bs[1]
        effects = {"saturation": {"v_max": float(np.sqrt(np.mean(out ** 2)) * rng.uniform(1.5, 3.0))}}
    else:
        bs = [rng.normal(0.0, 0.3, widths[l + 1]) for l in range(L)]
        effects = {"shot": {"q": float(np.exp(rng.uniform(np.log(0.01), np.log(0.03))))}}
    x = rng.uniform(-1.0, 1.0, (80, widths[0]))
    s = float(rng.uniform(0.03, 0.08))
    return widths, Ws, bs, x, s, effects, rng


def _campaign(rng, widths, Ws, bs, x, r, s, effects, taps, order="random", later=False):
    """One campaign on the chip: ``x`` (n, d_0), r shots each, every hidden layer tapped when
    ``taps``, the shots in ``order`` (random or blocked), after the first campaign when ``later``."""
    from gift_theory._measurement import Measurement
    from gift_theory._params import Layer

    from .contract_sim import simulate_contract
    from .time_physics import acquisition_times

    t = acquisition_times(rng, x.shape[0], r, order) + (1.0 if later else 0.0)
    y, tp, t = simulate_contract(rng, widths, Ws, bs, x, r, s, effects, t=t)
    return Measurement(x, y, tuple(Layer(W, b) for W, b in zip(Ws, bs)), tuple(tp) if taps else None, t, "tanh")


def _diag(key_seed, meas, design: bool):
    import jax

    from gift_theory.lab import diagnose

    d = diagnose(jax.random.PRNGKey(key_seed), meas, design=design)
    j = d.as_json()
    return {"explained": j["explained"], "explained_by": j["explained_by"], "verdict": j["verdict"],
            "mechanisms": [m["mechanism"] for m in j["mechanisms"][:3]],
            "ranking": [(e.get("with", []) + [e["effect"]], e["status"], e["p_value_after"]) for e in j["ranking"][:4]],
            "next_measurement": j.get("next_measurement")}, d


def _class_of(name: str) -> set:
    from gift_theory.effects import REGISTRY

    return {REGISTRY[e].mechanism for e in name.split("+")}


def one(scenario: str, i: int, seed: int) -> dict:
    spec = SCENARIOS[scenario]
    widths, Ws, bs, x, s, effects, rng = _chip(scenario, i, seed)
    r = 16
    t0 = time.time()
    first = _campaign(rng, widths, Ws, bs, x, r, s, effects, taps=False)
    out1, d1 = _diag(i, first, True)
    row = {"chip": i, "scenario": scenario, "arch": widths, "s": s, "effects": effects, "first": out1,
           "first_shots": int(first.n * first.r), "ambiguous": len(out1["explained_by"]) >= 2}
    if row["ambiguous"] and d1.next_measurement is not None:
        import jax

        from gift_theory.lab._design import Design, decide, designs, hypotheses

        nxt = d1.next_measurement
        hyps = hypotheses(list(d1.ranking), list(d1.mechanisms), list(d1.ambiguous_with))
        advised = Design(nxt["kind"], nxt["design"], np.asarray(nxt["_x"]), int(nxt["r"]), tuple(nxt["taps"]),
                         nxt["order"], bool(nxt["later"]))
        # the yardstick: the first design (the same inputs, no tap, the same order) with as many shots
        r_rep = max(r, -(-advised.shots() // first.n))
        repeat = designs(first)[0].at(r_rep // r) if r_rep % r == 0 else Design(
            "repeat", "the same inputs again", x, r_rep, (), "random")
        for name, dz in (("advised", advised), ("repeat", repeat)):
            camp = _campaign(rng, widths, Ws, bs, dz.x, dz.r, s, effects, taps=bool(dz.taps), order=dz.order,
                             later=dz.later)
            # the separating test of the design (the hypotheses as fitted on campaign 1, nothing refitted)
            rej = decide(jax.random.PRNGKey(i), hyps, first, dz, camp)
            left = [h for h, x in rej.items() if not x]
            o, _ = _diag(i + 1000, camp, False)
            one_model = o["explained"] and len(o["explained_by"]) == 1
            row[name] = dict(o, shots=int(camp.n * camp.r), rejected=rej,
                             decided=len(left) == 1, decided_right=bool(len(left) == 1
                                                                      and spec["class"] in _class_of(left[0])),
                             resolved=one_model,
                             right=bool(one_model and spec["class"] in _class_of(o["explained_by"][0])))
    row["seconds"] = time.time() - t0
    return row


def summary(path: str) -> dict:
    with open(path) as f:
        rows = [json.loads(line) for line in f if line.strip()]
    out = {}
    for sc in sorted({r["scenario"] for r in rows}):
        rs = [r for r in rows if r["scenario"] == sc]
        amb = [r for r in rs if r["ambiguous"] and "advised" in r]
        out[sc] = {"chips": len(rs), "ambiguous": len(amb),
                   "explained_by_one_first": sum(1 for r in rs if r["first"]["explained"]
                                                 and len(r["first"]["explained_by"]) == 1)}
        for name in ("advised", "repeat"):
            out[sc][name] = {"decided": sum(r[name]["decided"] for r in amb),
                             "decided_right": sum(r[name]["decided_right"] for r in amb),
                             "diagnosis_one_model": sum(r[name]["resolved"] for r in amb),
                             "diagnosis_one_model_right": sum(r[name]["right"] for r in amb),
                             "shots_mean": float(np.mean([r[name]["shots"] for r in amb])) if amb else None}
        out[sc]["predicted_power_mean"] = (float(np.mean([r["first"]["next_measurement"]["power"] for r in amb]))
                                           if amb else None)
        out[sc]["designs"] = sorted({r["first"]["next_measurement"]["kind"] for r in amb})
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.design_check", description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--scenario", choices=sorted(SCENARIOS), default="shot_vs_mult")
    p.add_argument("--chips", type=int, default=12)
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--seed", type=int, default=4848)
    p.add_argument("--summary", action="store_true")
    a = p.parse_args(argv)
    if a.summary:
        print(json.dumps(summary(a.out), indent=1))
        return 0
    done = set()
    if os.path.exists(a.out):
        with open(a.out) as f:
            done = {(json.loads(line)["scenario"], json.loads(line)["chip"]) for line in f if line.strip()}
    for i in range(a.first, a.first + a.chips):
        if (a.scenario, i) in done:
            continue
        row = one(a.scenario, i, a.seed)
        with open(a.out, "a") as f:
            f.write(json.dumps(row) + "\n")
        sys.stderr.write(f"[{a.scenario} {i}] ambiguous {row['ambiguous']} first {row['first']['explained_by']} "
                         f"advised {row.get('advised', {}).get('explained_by')} repeat "
                         f"{row.get('repeat', {}).get('explained_by')} ({row['seconds']:.0f} s)\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
