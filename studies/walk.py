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
effects are fitted (one by default, so loops over candidates do not inflate the count).
"""

from __future__ import annotations

import argparse
import collections
import json
import sys


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
    seq = []

    def prof(frame, event, arg):
        if event != "call":
            return
        callee = _module(frame)
        if callee is None or frame.f_back is None or _is_method(frame.f_code):
            return
        caller = frame.f_back.f_globals.get("__name__", "")
        if caller != callee and (not seq or seq[-1] != callee):
            seq.append(callee)

    sys.setprofile(prof)
    try:
        lab.diagnose(jax.random.PRNGKey(0), meas, candidates=list(candidates), second=0)
    finally:
        sys.setprofile(None)
    seen, returns, per = set(), 0, collections.Counter()
    for m in seq:
        per[m] += 1
        if m in seen:
            returns += 1
        seen.add(m)
    return {"walk": seq, "entries": dict(per), "returns": returns, "modules": len(seen)}


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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
