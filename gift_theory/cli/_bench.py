"""``gift bench``: estimator speed and efficiency against the machine's own matmul rate (CONTRACTS §4).

* ``matmul_gflops``: numpy float32 2048 x 2048 matmul, best of several, in this run.
* ``d0_deep_paper``: one estimate of d/ds grad J by the paper's estimator D^[0]
  (``score_paper``: one backward pass of the score-weighted loss) on
  784-500-250-250-100-50-10 with K1 = 1024 inputs x K2 = 8 draws, credited with
  6 x (number of weights) x K1 x K2 flops; compile excluded, best of ``--repeats``.
  ``d0_deep_pathwise`` is the same for the pathwise estimator.
* ``estimator_efficiency``: samples K1 K2 each estimator needs for a 5 % relative error
  |D_hat - D| / |D| of d/ds grad J at s0 = 0.1 (score_paper rescaled by -2/s0, the constant
  its derivation shows), from each estimator's own standard error on a run of
  ``--eff-K1`` x 8 samples; D is a long pathwise reference run over the same inputs, and
  the observed error of each run against it is reported next to the predicted one.

The deep net has Glorot-initialised weights and uniform random inputs with one-hot targets
(an estimator's cost does not depend on the data).
"""

from __future__ import annotations

import sys
import time

import numpy as np

DEEP = (784, 500, 250, 250, 100, 50, 10)


def add_arguments(parser):
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats per benchmark (best is reported)")
    parser.add_argument("--eff-K1", type=int, default=256, help="inputs per efficiency run (x 8 draws)")
    parser.add_argument("--ref-K2", type=int, default=64, help="draws per input of the pathwise reference")
    parser.add_argument("--quick", action="store_true", help="skip estimator_efficiency")


def matmul_gflops(n: int = 2048, repeats: int = 5) -> float:
    a = np.random.default_rng(0).standard_normal((n, n)).astype(np.float32)
    b = np.random.default_rng(1).standard_normal((n, n)).astype(np.float32)
    a @ b
    best = min(_timed(lambda: a @ b) for _ in range(repeats))
    return 2.0 * n ** 3 / best / 1e9


def _timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def _log(msg):
    sys.stderr.write(f"gift bench: {msg}\n")
    sys.stderr.flush()


def run(args) -> dict:
    import jax
    import jax.numpy as jnp

    import gift_theory as gt
    from .._errors import GiftInputError
    from ..estimators import d_ds_grad, paper_constant

    if args.repeats < 1 or args.eff_K1 < 2 or args.ref_K2 < 1:
        raise GiftInputError("gift bench: --repeats must be >= 1, --eff-K1 >= 2, --ref-K2 >= 1")
    roof = matmul_gflops()
    _log(f"numpy float32 matmul: {roof:.1f} GFLOP/s")
    arch = gt.Architecture(DEEP)
    params = gt.init_params(jax.random.PRNGKey(0), arch)
    K1, K2, s0 = 1024, 8, 0.1
    x = jax.random.uniform(jax.random.PRNGKey(1), (K1, DEEP[0]))
    y = jax.nn.one_hot(jnp.arange(K1) % DEEP[-1], DEEP[-1])
    phys = gt.awgn(s0)
    flops = 6.0 * arch.n_weights * K1 * K2
    benchmarks = []
    for name, method in (("d0_deep_paper", "score_paper"), ("d0_deep_pathwise", "pathwise")):
        def once(i):
            jax.block_until_ready(d_ds_grad(jax.random.PRNGKey(100 + i), params, x, y, phys, arch, method=method,
                                            K2=K2).mean)
        compile_s = _timed(lambda: once(0))
        best = min(_timed(lambda: once(i + 1)) for i in range(args.repeats))
        gflops = flops / best / 1e9
        benchmarks.append({"name": name, "seconds": best, "gflops": gflops, "ratio_to_matmul": gflops / roof,
                           "method": method, "K1": K1, "K2": K2, "arch": list(DEEP), "credited_flops": flops,
                           "first_call_seconds": compile_s})
        _log(f"{name}: {best:.3f} s, {gflops:.1f} GFLOP/s, {gflops / roof:.2f} of matmul")
    if not args.quick:
        benchmarks.append(_efficiency(args, arch, params, x, y, phys, roof))
    return {"matmul_gflops": roof, "benchmarks": benchmarks}


def _efficiency(args, arch, params, x, y, phys, roof) -> dict:
    import jax

    from ..estimators import d_ds_grad, paper_constant

    def flat(tree):
        return np.concatenate([np.asarray(a, np.float64).ravel() for a in jax.tree_util.tree_leaves(tree)])

    K2 = 8
    t0 = time.perf_counter()
    ref = d_ds_grad(jax.random.PRNGKey(7), params, x, y, phys, arch, method="pathwise", K2=args.ref_K2)
    D = flat(ref.mean)
    D_norm = float(np.linalg.norm(D))
    ref_rel_se = float(np.linalg.norm(flat(ref.se)) / D_norm)
    _log(f"reference: pathwise on {x.shape[0]} inputs x {args.ref_K2} draws, relative se {ref_rel_se:.4f}")
    n = min(args.eff_K1, x.shape[0])
    # a random subset of the reference's inputs: the estimator's error includes input sampling
    idx = np.random.default_rng(3).choice(x.shape[0], n, replace=False)
    per = {}
    for method in ("score_paper", "score", "pathwise", "fd"):
        t = time.perf_counter()
        est = d_ds_grad(jax.random.PRNGKey(11), params, x[idx], y[idx], phys, arch, method=method, K2=K2)
        c = paper_constant(phys.s) if method == "score_paper" else 1.0
        mean, se = flat(est.mean) / c, flat(est.se) / abs(c)
        samples = n * K2
        # relative error predicted from the estimator's own standard error, scaled to 5 %
        rel_pred = float(np.linalg.norm(se) / D_norm)
        need = samples * (rel_pred / 0.05) ** 2
        per[method] = {"samples_for_5pct": float(need), "relative_error_predicted": rel_pred,
                       "relative_error_observed": float(np.linalg.norm(mean - D) / D_norm), "samples": samples,
                       "seconds": time.perf_counter() - t}
        _log(f"{method}: {need:.3g} samples for 5 % (observed error {per[method]['relative_error_observed']:.3f} "
             f"at {samples}, predicted {rel_pred:.3f})")
    return {"name": "estimator_efficiency", "seconds": time.perf_counter() - t0, "gflops": None,
            "ratio_to_matmul": None, "s0": phys.s, "K2": K2, "reference_relative_se": ref_rel_se,
            "estimators": per,
            "pathwise_advantage_over_score_paper": per["score_paper"]["samples_for_5pct"]
            / per["pathwise"]["samples_for_5pct"]}


def render(r: dict) -> str:
    lines = [f"numpy float32 matmul: {r['matmul_gflops']:.1f} GFLOP/s", ""]
    for b in r["benchmarks"]:
        if b["name"] == "estimator_efficiency":
            lines.append(f"estimator_efficiency (s0={b['s0']:g}): samples K1*K2 for 5 % relative error")
            for m, e in b["estimators"].items():
                lines.append(f"  {m:12s} {e['samples_for_5pct']:12.4g}   (observed {e['relative_error_observed']:.3f}"
                             f" vs predicted {e['relative_error_predicted']:.3f} at {e['samples']} samples)")
            lines.append(f"  pathwise needs {b['pathwise_advantage_over_score_paper']:.0f}x fewer samples than score_paper")
        else:
            lines.append(f"{b['name']:18s} {b['seconds']:8.3f} s  {b['gflops']:7.1f} GFLOP/s  "
                         f"{b['ratio_to_matmul']:.2f} of matmul")
    return "\n".join(lines)
