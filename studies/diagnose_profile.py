"""Where ``gift diagnose`` spends its time, stage by stage, in one fresh process.

    python -m studies.diagnose_profile make FILE.npz        # the issue's file: 16-32-16-8, taps
    python -m studies.diagnose_profile run FILE.npz [--seed 0] [--json]

``make``: 240 inputs x 64 shots with taps, awgn s = 0.05 + crosstalk k = 0.04 + shot q = 0.002
(``gift simulate`` with those arguments). ``run``: ``gift diagnose FILE --no-design`` in this
process with one thread for the candidates (``GIFT_LAB_THREADS=1``: the stages run one after the
other, so each one's time is its own; the numbers do not depend on the threads), each stage
timed in wall and CPU seconds (``time.process_time``: on a shared machine the CPU seconds are the
measure) with the JAX compile time inside it:

    session      the split, the reference, the fitting half's moments, the baseline fit and score
    identify     the layer-wise identification (numpy, closed form)
    candidates   every candidate fitted, scored and checked, the second step (Monte Carlo draws)
    localise     one-step checks, residual profiles, signatures
    rest         mechanisms, the verdict, ambiguity

The stages are found by name in the pipeline's module (so the same script profiles an older
checkout whose stages have other names). Run it twice: the second process reads the compiled
programs from the persistent cache, as a user's second run does.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def _make(path: str) -> int:
    from gift_theory.cli._main import main

    return main(["simulate", "--arch", "16-32-16-8", "--inputs", "240", "--shots", "64", "--taps",
                 "--effect", "awgn=0.05", "--effect", "crosstalk=0.04", "--effect", "shot=0.002",
                 "--seed", "0", "--out", path])


def _wrap(module, name: str, label: str, clock: dict, method: str | None = None):
    """Time ``module.name`` (or its ``method``) under ``label``: wall, CPU and compile seconds."""
    from gift_theory.profiling import compile_totals

    owner = getattr(module, name, None)
    if owner is None:
        return False
    target = owner if method is None else getattr(owner, method, None)
    if target is None:
        return False
    raw = target.__func__ if isinstance(target, classmethod) or hasattr(target, "__func__") else target

    def timed(*a, **k):
        w0, c0, (s0, n0) = time.perf_counter(), time.process_time(), compile_totals()
        try:
            return raw(*a, **k)
        finally:
            s1, n1 = compile_totals()
            row = clock.setdefault(label, [0.0, 0.0, 0.0, 0])
            row[0] += time.perf_counter() - w0
            row[1] += time.process_time() - c0
            row[2] += s1 - s0
            row[3] += n1 - n0

    if method is None:
        setattr(module, name, timed)
    elif hasattr(target, "__func__"):  # a classmethod: rebind on the class
        setattr(owner, method, classmethod(lambda cls, *a, **k: timed(cls, *a, **k)))
    else:
        setattr(owner, method, timed)
    return True


def _run(path: str, seed: int, as_json: bool) -> int:
    os.environ["GIFT_LAB_THREADS"] = "1"
    w_start, c_start = time.perf_counter(), time.process_time()
    import jax

    from gift_theory import use_compilation_cache
    from gift_theory.profiling import compile_totals, listen

    use_compilation_cache()  # as the gift command does: a second process reads its programs from disk

    listen()
    from gift_theory.lab import _diagnose, load_measurement

    clock: dict = {}
    if hasattr(_diagnose.Session, "create"):
        _wrap(_diagnose, "Session", "session", clock, method="create")
    else:
        _wrap(_diagnose, "Session", "session", clock, method="__init__")
    _wrap(_diagnose, "identify", "identify", clock)
    _wrap(_diagnose, "rank_candidates", "candidates", clock) or _wrap(_diagnose, "_rank", "candidates", clock)
    _wrap(_diagnose, "with_alternatives", "candidates", clock) or _wrap(_diagnose, "_alternatives", "candidates", clock)
    _wrap(_diagnose, "_localise", "localise", clock)
    w_import = time.perf_counter() - w_start
    meas = load_measurement(path)
    w0, c0 = time.perf_counter(), time.process_time()
    res = _diagnose.diagnose(jax.random.PRNGKey(seed), meas)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    staged = [sum(v[i] for v in clock.values()) for i in range(3)]
    clock["rest"] = [wall - staged[0], cpu - staged[1], compile_totals()[0] - staged[2], 0]
    out = {"file": path, "explained": res.explained, "ranking": [c.name for c in res.ranking[:3]],
           "diagnose_wall": wall, "diagnose_cpu": cpu, "import_wall": w_import,
           "process_cpu": time.process_time() - c_start, "compile_seconds": compile_totals()[0],
           "programs": compile_totals()[1],
           "stages": {k: {"wall": v[0], "cpu": v[1], "compile": v[2], "programs": v[3]} for k, v in clock.items()}}
    if as_json:
        print(json.dumps(out))
        return 0
    print(f"{path}: diagnose {wall:.1f} s wall, {cpu:.1f} s CPU ({out['compile_seconds']:.1f} s compiling, "
          f"{out['programs']} programs); imports {w_import:.1f} s")
    for k, v in clock.items():
        print(f"  {k:<11s} {v[0]:7.2f} s wall {v[1]:7.2f} s CPU {v[2]:6.2f} s compiling")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.diagnose_profile")
    sub = ap.add_subparsers(dest="cmd", required=True)
    mk = sub.add_parser("make")
    mk.add_argument("file")
    rn = sub.add_parser("run")
    rn.add_argument("file")
    rn.add_argument("--seed", type=int, default=0)
    rn.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    return _make(a.file) if a.cmd == "make" else _run(a.file, a.seed, a.json)


if __name__ == "__main__":
    sys.exit(main())
