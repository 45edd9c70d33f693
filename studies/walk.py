"""The walk of one ``diagnose`` through the lab's modules: how often it returns to a module it had left.

    python -m studies.walk [--taps] [--candidates shot]

Simulates a small measurement (4-6-5-3, 60 inputs x 16 shots, hidden shot noise), then runs
``gift_theory.lab.diagnose`` on it under ``sys.setprofile`` and records every *cross-module
call*: a call whose callee lives in a module of ``gift_theory.lab`` other than its caller's.
The walk is the sequence of callee modules of those calls (repeats in a row collapsed). A
*return* is an entry into a module the walk had already entered and then left. Methods of
classes (the data types' accessors, ``Measurement.layers``) are not counted as entries. A pipeline
that reads top-down as stages enters each stage once per candidate model it scores; the
count is printed per module and in total, with ``--candidates`` fixing how many candidate
effects are fitted (one by default, so loops over candidates do not inflate the count). Also
printed: the walk of the pipeline's own calls (those made by ``lab._diagnose``, the stages in
the order it runs them), and every call against the stage order (a stage calling one that
runs after it; :data:`ORDER`).
"""

from __future__ import annotations

import argparse
import collections
import json
import sys


#: the pipeline's module and the order of its stages (issue 15's layout; unknown modules are not ranked)
PIPELINE = "gift_theory.lab._diagnose"
ORDER = tuple(f"gift_theory.lab.{m}" for m in ("_io", "_shots", "_qtest", "_channels", "_compare", "_fit_moments",
                                               "_offset_kinds", "_offset_fit", "_offset_null", "_offset_prior",
                                               "_fit", "identification", "_session", "_localise", "_mechanisms",
                                               "_verdict", "_ranking", "_diagnose"))


def _module(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    return name if name.startswith("gift_theory.lab") else None


def _is_method(code) -> bool:
    """A method of a class (a data type's accessor, ``Measurement.layers``): not a stage."""
    q = getattr(code, "co_qualname", code.co_name)
    return "." in q.replace(".<locals>.", "")


def walk(taps: bool = True, candidates=("shot",)) -> dict:
    import jax

    import gift_theory as gt
    from gift_theory import lab

    arch = gt.Architecture((4, 6, 5, 3))
    params = gt.init_params(jax.random.PRNGKey(1), arch)
    x = jax.random.uniform(jax.random.PRNGKey(2), (60, 4))
    physics = gt.Physics.create(s=0.1, shot=0.02)
    meas = lab.simulate_measurement(jax.random.PRNGKey(3), params, x, physics, shots=16, taps=taps)
    seq, driver, edges = [], [], set()

    def prof(frame, event, arg):
        if event != "call":
            return
        callee = _module(frame)
        if callee is None or frame.f_back is None or _is_method(frame.f_code):
            return
        caller = frame.f_back.f_globals.get("__name__", "")
        if caller != callee:
            if caller.startswith("gift_theory.lab"):
                edges.add((caller, callee))
            if not seq or seq[-1] != callee:
                seq.append(callee)
            if caller == PIPELINE and (not driver or driver[-1] != callee):
                driver.append(callee)

    sys.setprofile(prof)
    try:
        lab.diagnose(jax.random.PRNGKey(0), meas, candidates=list(candidates), second=0)
    finally:
        sys.setprofile(None)
    def count(walk):
        seen, returns, per = set(), 0, collections.Counter()
        for m in walk:
            per[m] += 1
            returns += m in seen
            seen.add(m)
        return dict(per), returns, len(seen)

    per, returns, modules = count(seq)
    dper, dreturns, _ = count(driver)
    # a call against the pipeline's order (a stage calling one that runs after it), where an order is known
    order = {m: i for i, m in enumerate(ORDER)}
    upward = sorted(f"{a.rsplit('.', 1)[-1]} -> {b.rsplit('.', 1)[-1]}" for a, b in edges
                    if a in order and b in order and order[b] > order[a])
    return {"walk": seq, "entries": per, "returns": returns, "modules": modules, "driver_walk": driver,
            "driver_entries": dper, "driver_returns": dreturns, "upward_calls": upward}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.walk", description=__doc__.splitlines()[0])
    p.add_argument("--no-taps", action="store_true")
    p.add_argument("--candidates", default="shot")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    r = walk(not a.no_taps, tuple(c for c in a.candidates.split(",") if c))
    if a.json:
        print(json.dumps(r))
    else:
        print(" -> ".join(m.rsplit(".", 1)[-1] for m in r["walk"]))
        print(f"entries per module: {r['entries']}")
        print(f"returns to a module already left: {r['returns']} ({r['modules']} modules)")
        print("the pipeline's own calls: " + " -> ".join(m.rsplit(".", 1)[-1] for m in r["driver_walk"]))
        print(f"  returns there: {r['driver_returns']}; calls against the stage order: {r['upward_calls'] or 'none'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
