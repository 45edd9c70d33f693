"""Algorithm 1 (alg:GIFT) as printed and corrected; Theorem 2 (thm:ft-guarantee) and the
text's claim that the selection step includes w0 so GIFT never makes the loss worse."""

from __future__ import annotations

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

import gift_theory as gt

from . import _mc, _onn
from ._record import combine, fmt, record, sign_verdict


def make_eval(key, x, y, physics, arch, K2: int):
    """Eval_w(K1, K2) (eq. def:Eval) on a simulated chip: every call draws fresh noise
    (a chip's noise cannot be replayed); returns the K1 per-input losses."""
    counter = itertools.count()

    def eval_fn(w):
        return gt.per_input_loss(jax.random.fold_in(key, next(counter)), w, x, y, physics, arch, K2)

    return eval_fn


def algorithm1(eval_fn, w0, D, eta: float, *, max_iter: int = 50, keep_w0: bool = False, delta: float | None = None):
    """Directional search and selection of alg:GIFT.

    Candidates w^[c,+-] = w0 +- c eta D (the rays from w0; the printed w^[i] of line
    gift:Directional-search read as the previous point of the same ray). The search stops
    at the first i with max(L^[i,+], L^[i,-]) >= L^[0] (line gift:Directional-evaluation).

    Printed selection (``keep_w0=False``, line giftalg:selection): argmin of Eval over
    c in [i] = {1..i}, both signs -- w0 is not a candidate.
    Corrected selection (``keep_w0=True``): w0 is a candidate, and with ``delta`` a
    candidate replaces w0 only if a one-sided paired test (per-input differences of its
    Eval against L^[0]) rejects "not better" at level ``delta``.

    Returns
    -------
    (w_ft, info) with info = {"iterations", "chosen": (c, sign) or (0, 0)}
    """
    flat0, unravel = gt.flatten(w0)
    D = jnp.asarray(D, flat0.dtype)
    L0 = eval_fn(w0)
    cands = []
    i = 0
    while i < max_iter:
        i += 1
        worst = -math.inf
        for sign in (+1, -1):
            w = unravel(flat0 + sign * i * eta * D)
            losses = eval_fn(w)
            cands.append((i, sign, w, losses))
            worst = max(worst, float(losses.mean()))
        if worst >= float(L0.mean()):
            break
    best, best_val, chosen = None, math.inf, (0, 0)
    if keep_w0:
        best, best_val = w0, float(L0.mean())
    z_delta = float(stats.norm.isf(delta)) if delta is not None else None
    for c, sign, w, losses in cands:
        val = float(losses.mean())
        if z_delta is not None:
            d = losses - L0
            se = d.std(ddof=1) / math.sqrt(d.size)
            if not d.mean() + z_delta * se < 0:
                continue
        if val < best_val:
            best, best_val, chosen = w, val, (c, sign)
    return best, {"iterations": i, "chosen": chosen}


def _true_difference(key, wa, wb, setup, s, K2):
    phys = setup.problem.physics.replace(s=s)
    d = gt.paired_difference(key, wa, wb, setup.problem.x, setup.problem.y, phys, setup.problem.arch, K2=K2)
    return float(d.mean), float(d.se)


def theorem2_guarantee(key=None, precise: bool = False) -> dict:
    """thm:ft-guarantee on a compact tanh ONN: GIFT (printed D^[0], printed Algorithm 1)
    with small eta and large K1, K2 lowers J_st."""
    key = jax.random.PRNGKey(2) if key is None else key
    st_ = _onn.setup(precise)
    p = st_.problem
    s0, st = st_.s0, st_.st
    D = _mc.d0_printed(jax.random.fold_in(key, 0), st_.w0, p.x, p.y, p.physics.replace(s=s0), p.arch,
                       K2=64 if precise else 32)
    Dn = float(np.linalg.norm(D.mean))
    th1 = st_.theorem1
    eta = 0.5 * abs(th1["alpha"]) * th1["v_norm"] / Dn        # half the quadratic-model step: "eta small"
    ev = make_eval(jax.random.fold_in(key, 1), p.x, p.y, p.physics.replace(s=st), p.arch, K2=32 if precise else 16)
    w_ft, info = algorithm1(ev, st_.w0, D.mean, eta)
    diff, se = _true_difference(jax.random.fold_in(key, 3), w_ft, st_.w0, st_, st, K2=128 if precise else 64)
    verdict, z = sign_verdict(diff, se, "negative")
    return record(
        "theorem2_guarantee",
        "thm:ft-guarantee, eq. claim thoerem GIFT 2: for small eta and large K1, K2, J_st(w_ft) < J_st(w0) "
        "for w_ft = GIFT(s0; eta, K1, K2) (Algorithm 1 with the printed D^[0])",
        verdict,
        f"tanh ONN {p.arch}, teacher data n={p.x.shape[0]}, s0={s0:g}, st={st:g}, w0 trained at s0; printed D^[0] "
        f"(K2={64 if precise else 32} per input), eta={fmt(eta)}, search stopped at i={info['iterations']}, "
        f"chose c={info['chosen'][0]} sign={info['chosen'][1]:+d}; J_st(w_ft) - J_st(w0) = {fmt(diff)} +- {fmt(se)} "
        f"(paired, fresh draws; z = {z:.1f}, one-sided at 1-1e-5). The printed D^[0] estimates -(s0/2) d/ds grad J "
        f"(see d0_limit), a rescaling that the two-sided line search absorbs",
        correction=None if verdict != "fails" else "see gift_never_worse for the corrected selection",
        counterexample=None if verdict != "fails" else {"difference": diff, "se": se})


def _clopper_pearson(k, n, conf):
    lo = stats.beta.ppf((1 - conf) / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - (1 - conf) / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def gift_never_worse(key=None, precise: bool = False) -> dict:
    """The text: the selection step includes w0, so GIFT never makes the loss worse.
    Tested on the printed Algorithm 1 with st = s0 (no misspecification: every step away
    from the critical point w0 is worse), then the corrected selection."""
    key = jax.random.PRNGKey(3) if key is None else key
    st_ = _onn.setup(precise)
    p = st_.problem
    s0 = st_.s0
    phys0 = p.physics.replace(s=s0)
    D = _mc.d0_printed(jax.random.fold_in(key, 0), st_.w0, p.x, p.y, phys0, p.arch, K2=32)
    flat0, unravel = gt.flatten(st_.w0)
    eta = 0.05 * float(jnp.linalg.norm(flat0)) / float(np.linalg.norm(D.mean))
    K2e = 16
    # printed algorithm, one run
    ev = make_eval(jax.random.fold_in(key, 1), p.x, p.y, phys0, p.arch, K2=K2e)
    w_ft, info = algorithm1(ev, st_.w0, D.mean, eta)
    diff, se = _true_difference(jax.random.fold_in(key, 2), w_ft, st_.w0, st_, s0, K2=64)
    worse_v, z = sign_verdict(diff, se, "positive")
    # corrected selection: w0 kept, paired one-sided test at level delta; replicate runs
    delta = 0.05
    R = 120 if precise else 40
    worse = 0
    truth = {}
    for r in range(R):
        ev = make_eval(jax.random.fold_in(key, 100 + r), p.x, p.y, phys0, p.arch, K2=K2e)
        w_c, inf = algorithm1(ev, st_.w0, D.mean, eta, keep_w0=True, delta=delta)
        if inf["chosen"] != (0, 0):
            if inf["chosen"] not in truth:
                truth[inf["chosen"]] = _true_difference(jax.random.fold_in(key, 7), w_c, st_.w0, st_, s0, K2=64)
            worse += truth[inf["chosen"]][0] > 0
    lo, hi = _clopper_pearson(worse, R, 0.95)
    lo_strict, _ = _clopper_pearson(worse, R, 1 - 1e-5)
    corrected_v = "holds" if hi <= 2 * delta else ("fails" if lo_strict > delta else "inconclusive")
    # "never worse" is universal: one significantly worse run refutes it; a run that is not
    # worse (even a significantly better one) cannot confirm it
    verdict = "fails" if worse_v == "holds" else "inconclusive"
    correction = None
    if corrected_v == "holds":
        correction = (f"keep w0 among the candidates and let a candidate replace w0 only if a one-sided paired test "
                      f"of its Eval against L^[0] (per-input differences) rejects 'not better' at level delta; then "
                      f"P(J_st(w_ft) > J_st(w0)) <= delta per accepted candidate: in {R} runs at st = s0 with "
                      f"delta = {delta}, {worse} returned a worse point (95% upper bound {fmt(hi)})")
    return record(
        "gift_never_worse",
        "alg:GIFT, line giftalg:selection (argmin over c in [i], w0 not a candidate) and the text's claim that the "
        "selection includes w0 so that GIFT never makes J_st worse",
        verdict,
        f"printed Algorithm 1 at st = s0 = {s0:g} (w0 critical, eta ||D|| = 5% of ||w0||): stopped at i = "
        f"{info['iterations']}, returned c={info['chosen'][0]} sign={info['chosen'][1]:+d} with J_st(w_ft) - J_st(w0) = "
        f"{fmt(diff)} +- {fmt(se)} (z = {z:.1f}); corrected selection: {worse}/{R} runs worse "
        f"(95% CI [{fmt(lo)}, {fmt(hi)}])",
        correction=correction,
        counterexample=None if verdict != "fails" else {"s0": s0, "st": s0, "eta": eta, "difference": diff, "se": se,
                                                         "chosen": list(info["chosen"])})
