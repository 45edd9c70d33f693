"""``python -m paper_figures --profile``: where the time of a paper-scale sweep goes.

One fresh process (so that compilation is measured from cold) trains one net of the paper
scale in silico (30 epochs on mnist5k, into a temporary cache), then runs GIFT points on it as
the sweep's job does (``finetune_on`` with run_finetune's defaults), each with the chip's true
noise of a different law, so a structural change of the physics is measured too. Every phase
(:mod:`gift_theory.profiling`) reports wall seconds, seconds JAX spent compiling inside it and
the programs it compiled; every total carries its credited floating-point work and the ratio
of its rate to numpy's float32 matmul rate measured in the same run (the roof).

Credited work (what the arithmetic needs, whatever the code does): a forward pass is
2 x (number of weights) flops per sample, a weight gradient 6 x, the forward-over-reverse
d/ds grad and Hessian-vector products 6 x as ``gift bench`` credits them.

The JSON goes to stdout (``--json``) or a table to stdout; ``--out FILE`` also writes it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

NETS = {"deep": "784-500-250-250-100-50-10", "shallow": "784-500-100-100-10"}
#: the points profiled after training: (label, noise_kind, st) at s0 = 0.1
POINTS = (("first", "awgn", 0.2), ("steady", "awgn", 0.05), ("new_law", "laplace", 0.1), ("steady2", "awgn", 0.1))


def _credited(arch, n_train: int, n_test: int, *, budget: float, K1: int, K2: int, referee_K2: int,
              direction_K2: int = 16, curvature_K2: int = 8, prediction: bool = False,
              prediction_K2: int = 8, moved: bool = True) -> dict:
    """Credited flops of one GIFT point by phase (run_finetune's defaults).

    The referee scores w0 and, if the method ``moved`` (returned weights other than w0), the
    fine-tuned weights on training and test data (and, with a prediction, the line search's
    candidate on training data): each distinct weight set once. The prediction is two
    forward-mode derivatives (4 x weights flops per sample) at s0 and st.
    """
    W = arch.n_weights
    sets = 1 + bool(moved)
    out = {"referee": 2.0 * W * ((sets + prediction) * n_train + sets * n_test) * referee_K2,
           "method/direction": 6.0 * W * n_train * direction_K2,
           "method/curvature": 6.0 * W * n_train * curvature_K2,
           "method/pair_se": 2.0 * W * K1 * K2 * 2,
           "method/chip": 2.0 * W * K1 * K2 * budget}
    if prediction:
        out["prediction"] = 4.0 * W * n_train * prediction_K2 * 2
    return out


def _child(net: str, epochs: int, s0: float, seed: int) -> dict:
    """Train one net and run the GIFT points, in this (fresh) process."""
    import dataclasses

    import jax

    import gift_theory as gt
    from gift_theory import cast_params as cast
    from gift_theory.profiling import PhaseClock, compile_totals, compiled_functions, listen
    from gift_theory.profiling import matmul_gflops
    from gift_theory.data import load_dataset
    from gift_theory.finetune import finetune_on, true_physics
    from gift_theory.training import default_config, load_or_train

    from ._jobs import true_noise

    listen()
    roof = matmul_gflops()
    arch = gt.Architecture.parse(NETS[net])
    ds = load_dataset("mnist5k")
    config = dataclasses.replace(default_config("mnist5k", arch), epochs=epochs)
    out = {"net": net, "arch": str(arch), "dataset": "mnist5k", "s0": s0, "seed": seed, "matmul_gflops": roof,
           "jax": jax.__version__, "compilation_cache_dir": jax.config.jax_compilation_cache_dir, "runs": []}
    with tempfile.TemporaryDirectory() as cache, PhaseClock() as clock:
        t0 = time.perf_counter()
        w0, info = load_or_train("mnist5k", arch, s0=s0, seed=seed, config=config, cache=cache, progress=False)
        wall = time.perf_counter() - t0
    flops = 6.0 * arch.n_weights * ds.x_train.shape[0] * epochs
    train = {"label": "training", "epochs": epochs, "seconds": wall, "phases": clock.phases,
             "credited_flops": {"train": flops}}
    sgd = clock.phases.get("train", {})
    train["sgd_seconds_excluding_compile"] = sgd.get("seconds", 0.0) - sgd.get("compile_seconds", 0.0)
    train["ratio_to_matmul"] = flops / max(train["sgd_seconds_excluding_compile"], 1e-9) / 1e9 / roof
    train["test_accuracy"] = info.get("test_accuracy")
    out["runs"].append(train)
    _log(f"training {epochs} epochs: {wall:.1f} s (compile {sgd.get('compile_seconds', 0):.1f} s), "
         f"{train['ratio_to_matmul']:.2f} of matmul")
    w0 = cast(w0, jax.numpy.float32)
    from gift_theory import memo as _memo

    _memo.use_folder(None)
    os.environ.pop("GIFT_MEMO_DIR", None)  # nothing on disk either
    for label, kind, st in POINTS:
        s_true, effects = true_noise(kind, st)
        physics = true_physics(s_true, effects)
        # every point does its whole work (the credited flops count it): nothing from the memo
        _memo.clear()
        c0, n0 = compile_totals()
        with PhaseClock() as clock:
            t0 = time.perf_counter()
            res = finetune_on(ds, arch, w0, s0=s0, physics=physics, method="gift", seed=seed, **_predict(s_true, st))
            wall = time.perf_counter() - t0
        c1, n1 = compile_totals()
        credited = _credited(arch, ds.x_train.shape[0], ds.x_test.shape[0], budget=20, K1=ds.x_train.shape[0],
                             K2=1, referee_K2=32, prediction="prediction" in clock.phases,
                             moved=_memo.digest(res["params"]) != _memo.digest(w0))
        total = sum(credited.values())
        run = {"label": label, "noise_kind": kind, "st": st, "seconds": wall, "compile_seconds": c1 - c0,
               "compiles": n1 - n0, "phases": clock.phases, "credited_flops": credited,
               "ratio_to_matmul": total / wall / 1e9 / roof,
               "numbers": {k: res[k] for k in ("loss_before", "loss_after", "accuracy_before", "accuracy_after",
                                               "test_loss_before", "test_loss_after", "test_accuracy_before",
                                               "test_accuracy_after", "in_situ_evaluations")}}
        for name, p in clock.phases.items():
            if name in credited and p["seconds"] > 0:
                p["ratio_to_matmul"] = credited[name] / p["seconds"] / 1e9 / roof
        out["runs"].append(run)
        _log(f"point {label} ({kind}, st={st}): {wall:.1f} s, of which compiling {c1 - c0:.1f} s ({n1 - n0} programs),"
             f" {run['ratio_to_matmul']:.3f} of matmul")
    out["compiled_functions"] = compiled_functions()
    return out


def _predict(s_true: float, st: float) -> dict:
    """The sweep job's prediction option, where finetune_on knows it (absent before it did)."""
    import inspect

    from gift_theory.finetune import finetune_on

    if "predict_s" not in inspect.signature(finetune_on).parameters:
        return {}
    from ._jobs import prediction_level

    return {"predict_s": prediction_level(s_true, st)}


def _log(msg: str) -> None:
    sys.stderr.write(f"[profile] {msg}\n")
    sys.stderr.flush()


def profile(net: str = "deep", epochs: int = 30, s0: float = 0.1, seed: int = 0, compile_cache: str | None = None,
            env: dict | None = None) -> dict:
    """Run :func:`_child` in a fresh Python process; returns its JSON.

    compile_cache : a folder for JAX's persistent compilation cache (``GIFT_COMPILATION_CACHE``);
        None: a new empty folder (a cold start), "off": no persistent cache.
    """
    tmp = None
    if compile_cache is None:
        tmp = tempfile.mkdtemp(prefix="gift-profile-xla-")
        compile_cache = tmp
    child_env = dict(os.environ, GIFT_COMPILATION_CACHE=compile_cache, **(env or {}))
    cmd = [sys.executable, "-m", "paper_figures._profile", "--child", "--net", net, "--epochs", str(epochs),
           "--s0", str(s0), "--seed", str(seed)]
    proc = subprocess.run(cmd, env=child_env, stdout=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"profile child failed with status {proc.returncode}")
    return json.loads(proc.stdout)


def render(r: dict) -> str:
    lines = [f"{r['net']} net {r['arch']} on {r['dataset']}, s0={r['s0']:g}, seed {r['seed']}; "
             f"numpy matmul {r['matmul_gflops']:.1f} GFLOP/s (jax {r['jax']})"]
    for run in r["runs"]:
        head = f"{run['label']}" + (f" ({run['noise_kind']}, st={run['st']:g})" if "noise_kind" in run else "")
        lines.append(f"  {head}: {run['seconds']:.1f} s wall, {run['ratio_to_matmul']:.3f} of matmul")
        for name, p in sorted(run["phases"].items()):
            ratio = f", {p['ratio_to_matmul']:.3f} of matmul" if "ratio_to_matmul" in p else ""
            lines.append(f"      {name:24s} {p['seconds']:8.2f} s  (compile {p['compile_seconds']:6.2f} s, "
                         f"{p['compiles']:3d} programs, {p['calls']} calls{ratio})")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m paper_figures --profile", description=__doc__.splitlines()[0])
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--net", default="deep", choices=tuple(NETS))
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--s0", type=float, default=0.1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--compile-cache", default=None, metavar="DIR",
                        help="persistent compilation cache folder ('off' for none; default: a new empty one)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--out", default=None, metavar="FILE", help="also write the JSON here")
    args = parser.parse_args(argv)
    if args.child:
        sys.stdout.write(json.dumps(_child(args.net, args.epochs, args.s0, args.seed), default=float) + "\n")
        return 0
    r = profile(args.net, args.epochs, args.s0, args.seed, args.compile_cache)
    if args.out:
        from gift_theory import atomic_write_bytes

        atomic_write_bytes(args.out, (json.dumps(r, indent=1, default=float) + "\n").encode())
    sys.stdout.write((json.dumps(r, default=float) if args.json else render(r)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
