"""Benchmarks: estimator speed and efficiency against the machine's own matmul rate (the work of
``gift bench``, reference §4; :func:`run_benchmarks`).

* ``matmul_gflops``: numpy float32 2048 x 2048 matmul, best of 10, in this run (on a shared
  machine both this rate and the timings below are best-of, so that a busy neighbour lowers
  neither the roof nor the estimate more than the other).
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

* ``referee_deep``: the referee of one fine-tuning point on the same net: loss and accuracy of
  two weight sets (before and after) on 4000 + 1000 inputs x 32 draws, one pass over shared
  draws, credited with 2 x (number of weights) flops per sample and weight set (the forward
  products; the draws are not credited); compile excluded, best of ``--repeats``.
* ``d0_deep_paper_torch`` (only where PyTorch is installed; gift does not need it): the same
  estimate written as a careful batched PyTorch program (one forward pass of all K1 K2
  samples, one backward pass of the score-weighted loss), the peer the issue names, timed in
  the same run so that the comparison is a ratio on one machine.
* ``d0_deep_million``: K1 K2 = 10^6 samples (K1 = 125000 inputs x K2 = 8) on the same net, in
  a fresh process whose peak resident memory is read from the OS (``peak_rss_gb``; the
  estimators work in blocks of ``chunk`` samples, so memory must not grow with K1 K2).

The deep net has Glorot-initialised weights and uniform random inputs with one-hot targets
(an estimator's cost does not depend on the data).
"""

from __future__ import annotations

import sys
import time

import numpy as np

DEEP = (784, 500, 250, 250, 100, 50, 10)


def matmul_gflops(n: int = 2048, repeats: int = 10) -> float:
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
    if _LOG[0] is not None:
        _LOG[0](msg)


#: where progress lines go (set by :func:`run_benchmarks`)
_LOG = [None]


def run_benchmarks(*, repeats: int = 5, eff_K1: int = 256, ref_K2: int = 64, quick: bool = False, log=None) -> dict:
    """Every benchmark of the module docstring; the reference §4 ``gift bench`` object.

    Parameters
    ----------
    repeats : timed repeats per benchmark (the best is reported)
    eff_K1 : inputs per efficiency run (x 8 draws); ref_K2 : draws per input of the pathwise reference
    quick : skip estimator_efficiency and d0_deep_million
    log : ``log(line)`` for progress (default silent)

    Returns
    -------
    dict ``{"matmul_gflops": float, "benchmarks": [{"name", "seconds", "gflops", "ratio_to_matmul", ...}]}``
    """
    import jax
    import jax.numpy as jnp

    import gift_theory as gt
    from ._errors import GiftInputError
    from .estimators import d_ds_grad

    if repeats < 1 or eff_K1 < 2 or ref_K2 < 1:
        raise GiftInputError("gift bench: --repeats must be >= 1, --eff-K1 >= 2, --ref-K2 >= 1")
    _LOG[0] = log
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
        best = min(_timed(lambda: once(i + 1)) for i in range(repeats))
        gflops = flops / best / 1e9
        benchmarks.append({"name": name, "seconds": best, "gflops": gflops, "ratio_to_matmul": gflops / roof,
                           "method": method, "K1": K1, "K2": K2, "arch": list(DEEP), "credited_flops": flops,
                           "first_call_seconds": compile_s})
        _log(f"{name}: {best:.3f} s, {gflops:.1f} GFLOP/s, {gflops / roof:.2f} of matmul")
    benchmarks.append(_referee(arch, params, roof, repeats))
    peer = _torch_peer(params, x, y, s0, K2, repeats)
    if peer is not None:
        gflops = flops / peer["seconds"] / 1e9
        peer.update({"name": "d0_deep_paper_torch", "gflops": gflops, "ratio_to_matmul": gflops / roof, "K1": K1,
                     "K2": K2, "arch": list(DEEP), "credited_flops": flops,
                     "gift_speedup": peer["seconds"] / benchmarks[0]["seconds"]})
        benchmarks.append(peer)
        _log(f"d0_deep_paper_torch: {peer['seconds']:.3f} s ({peer['gift_speedup']:.2f}x the time of gift's)")
    else:
        _log("d0_deep_paper_torch: PyTorch not installed, peer skipped")
    if not quick:
        benchmarks.append(_efficiency(eff_K1, ref_K2, arch, params, x, y, phys, roof))
        benchmarks.append(_million(roof))
    return {"matmul_gflops": roof, "benchmarks": benchmarks}


def _referee(arch, params, roof: float, repeats: int) -> dict:
    """``referee_deep``: one point's referee (two weight sets, train + test sizes of mnist5k)."""
    import jax
    import jax.numpy as jnp

    import gift_theory as gt
    from .finetune._problem import referee_scores

    n, K2 = 5000, 32
    x = jax.random.uniform(jax.random.PRNGKey(3), (n, DEEP[0]))
    labels = jnp.arange(n) % DEEP[-1]
    y = jax.nn.one_hot(labels, DEEP[-1])
    after = gt.init_params(jax.random.PRNGKey(4), arch)
    phys = gt.awgn(0.1)

    def once():
        for a, b in ((0, 4000), (4000, n)):  # the training and test splits, as a point scores them
            referee_scores([params, after], x[a:b], y[a:b], labels[a:b], phys, arch, K2=K2)

    first = _timed(once)
    best = min(_timed(once) for _ in range(repeats))
    flops = 2.0 * arch.n_weights * n * K2 * 2
    gflops = flops / best / 1e9
    _log(f"referee_deep: {best:.3f} s, {gflops:.1f} GFLOP/s, {gflops / roof:.2f} of matmul")
    return {"name": "referee_deep", "seconds": best, "gflops": gflops, "ratio_to_matmul": gflops / roof,
            "inputs": n, "K2": K2, "weight_sets": 2, "arch": list(DEEP), "credited_flops": flops,
            "first_call_seconds": first}


def _torch_peer(params, x, y, s0: float, K2: int, repeats: int):
    """The paper's estimator D^[0] as a careful batched PyTorch program; None without PyTorch."""
    try:
        import torch
    except ImportError:
        return None
    import os

    torch.set_num_threads(os.cpu_count() or 1)
    Ws = [torch.tensor(np.asarray(p.W), requires_grad=True) for p in params]
    bs = [torch.tensor(np.asarray(p.b), requires_grad=True) for p in params]
    X = torch.tensor(np.asarray(x)).repeat_interleave(K2, 0)
    Y = torch.tensor(np.asarray(y)).repeat_interleave(K2, 0)
    gen = torch.Generator().manual_seed(0)

    def once():
        n = X.shape[0]
        xi = torch.randn(X.shape, generator=gen)
        Q, D = (xi * xi).sum(1), X.shape[1]
        a = X + s0 * xi
        for l, (W, b) in enumerate(zip(Ws, bs), start=1):
            nw = torch.randn((n, W.shape[0]), generator=gen)
            Q, D = Q + (nw * nw).sum(1), D + W.shape[0]
            z = torch.addmm(b, a, W.t()) + s0 * nw
            if l < len(Ws):
                na = torch.randn((n, W.shape[0]), generator=gen)
                Q, D = Q + (na * na).sum(1), D + W.shape[0]
                a = torch.tanh(z) + s0 * na
            else:
                a = z
        loss = ((Q - D) / n * ((Y - a) ** 2).sum(1)).sum()
        return [-0.5 * g for g in torch.autograd.grad(loss, Ws + bs)]

    first = _timed(once)
    best = min(_timed(once) for _ in range(repeats))
    return {"seconds": best, "first_call_seconds": first, "method": "score_paper (PyTorch " + torch.__version__ + ")",
            "peer": True}


def _million(roof: float) -> dict:
    """d0_deep_million in a fresh process, so that its peak resident memory is its own."""
    import json
    import subprocess

    _log("d0_deep_million: K1 K2 = 10^6 on the deep net in a fresh process (about a minute) ...")
    proc = subprocess.run([sys.executable, "-m", "gift_theory._bench", "million"], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"d0_deep_million failed: {proc.stderr.strip().splitlines()[-1:]}")
    r = json.loads(proc.stdout)
    r["ratio_to_matmul"] = r["gflops"] / roof
    _log(f"d0_deep_million: {r['seconds']:.1f} s, peak memory {r['peak_rss_gb']:.2f} GB")
    return r


def _million_child() -> dict:
    import resource

    import jax
    import jax.numpy as jnp

    import gift_theory as gt
    from .estimators import d_ds_grad

    arch = gt.Architecture(DEEP)
    params = gt.init_params(jax.random.PRNGKey(0), arch)
    K1, K2 = 125_000, 8
    x = jax.random.uniform(jax.random.PRNGKey(1), (K1, DEEP[0]))
    y = jax.nn.one_hot(jnp.arange(K1) % DEEP[-1], DEEP[-1])
    t = time.perf_counter()
    est = d_ds_grad(jax.random.PRNGKey(2), params, x, y, gt.awgn(0.1), arch, method="score_paper", K2=K2)
    jax.block_until_ready((est.mean, est.se))
    seconds = time.perf_counter() - t
    flops = 6.0 * arch.n_weights * K1 * K2
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9  # Linux reports KiB
    return {"name": "d0_deep_million", "seconds": seconds, "gflops": flops / seconds / 1e9, "method": "score_paper",
            "K1": K1, "K2": K2, "arch": list(DEEP), "credited_flops": flops, "peak_rss_gb": peak,
            "input_data_gb": K1 * DEEP[0] * 4 / 1e9}


def _efficiency(eff_K1, ref_K2, arch, params, x, y, phys, roof) -> dict:
    import jax

    from .estimators import d_ds_grad, paper_constant

    def flat(tree):
        return np.concatenate([np.asarray(a, np.float64).ravel() for a in jax.tree_util.tree_leaves(tree)])

    K2 = 8
    t0 = time.perf_counter()
    ref = d_ds_grad(jax.random.PRNGKey(7), params, x, y, phys, arch, method="pathwise", K2=ref_K2)
    D = flat(ref.mean)
    D_norm = float(np.linalg.norm(D))
    ref_rel_se = float(np.linalg.norm(flat(ref.se)) / D_norm)
    _log(f"reference: pathwise on {x.shape[0]} inputs x {ref_K2} draws, relative se {ref_rel_se:.4f}")
    n = min(eff_K1, x.shape[0])
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


if __name__ == "__main__" and sys.argv[1:] == ["million"]:
    import json

    sys.stdout.write(json.dumps(_million_child()) + "\n")
