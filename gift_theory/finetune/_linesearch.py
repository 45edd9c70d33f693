"""Algorithm 1 (GIFT) as printed, and the repaired line search used by ``gift`` and the
direction rivals.

Printed (alg:GIFT): L^[0] = Eval(w0); repeat w^[i+1,+-] = w^[i] +- eta D^[0], evaluate both,
i <- i + 1, until L^[i,+] v L^[i,-] >= L^[0] (v = max: stop as soon as either side is no
better than L^[0]); return the argmin of Eval over {w^[c,.] : c in [i]} -- w0 is not a
candidate. The iterate w^[i] is never defined for i >= 1; we read the line as the ray
w^[c,+-] = w0 +- c eta D^[0].

Repaired (``paired_line_search``): a unit direction u; the loss change along it is
predicted to second order, dJ(a) = J(w0) - J(w0 + a u) ~ a C1 - a^2 C2 / 2, with C2 =
u^T H u from the model (in silico, free) and C1 measured on the chip from a symmetric
pair of probes; eta = argmax = C1 / C2, refined by a weighted least-squares fit of
(C1, C2) to every point measured. All chip evaluations use the same inputs, so each
comparison with w0 is a paired difference over inputs (the input-to-input spread cancels).
The best measured point is then confirmed on fresh shots against a fresh Eval of w0 and
accepted only if the paired improvement is significant; otherwise w0 is returned -- no
winner's curse, never worse than w0 except with small probability. The confirmation looks
at its running mean after every fresh pair (it stops as soon as it is convinced, to save
chip evaluations), so one look at level alpha = P(Z > z_accept) would not do: k looks at a
fixed z inflate the false acceptance rate (at the optimum of a stub bowl, 11 in 1000 runs
instead of 0.62 %). Each look uses the Bonferroni boundary Phi^-1(1 - alpha / k), k the
looks the budget allows, which keeps the overall rate at most alpha.
"""

from __future__ import annotations

import math

import jax
import numpy as np
from scipy import stats

from .._objective import per_input_loss
from .._phases import phase
from ._tree import axpy, norm, unit, vdot


def _mean_se(d):
    d = np.asarray(d, np.float64)
    return float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.shape[0]))


def gift_printed(problem, D0, eta: float, *, max_iter: int = 1000, keep_w0: bool = False):
    """Algorithm 1 exactly as printed (ray reading, see module docstring).

    Stops also when the chip budget cannot pay for the next pair of evaluations.
    ``keep_w0``: w0 (its Eval L^[0]) is a candidate of the final argmin too, as the paper's
    text says of its selection ("GIFT never returns weights worse than w0") while the printed
    algorithm does not; the returned step is then 0 when no candidate measured below L^[0].

    Returns
    -------
    params, info (iterations, the Eval values, whether the budget stopped it)
    """
    w0 = problem.w0
    L0 = float(np.mean(problem.eval_chip(w0)))
    cands, i, stopped_by_budget = [], 0, False
    while i < max_iter:
        if problem.evaluations_left() < 2 - 1e-9:
            stopped_by_budget = True
            break
        wp = axpy((i + 1) * eta, D0, w0)
        wm = axpy(-(i + 1) * eta, D0, w0)
        Lp = float(np.mean(problem.eval_chip(wp)))
        Lm = float(np.mean(problem.eval_chip(wm)))
        cands += [(Lp, wp, +(i + 1)), (Lm, wm, -(i + 1))]
        i += 1
        if max(Lp, Lm) >= L0:  # the printed stopping rule L^[i,+] v L^[i,-] >= L^[0]
            break
    if not cands:  # no budget for even one pair: the printed algorithm cannot run
        return w0, {"iterations": 0, "L0": L0, "stopped_by_budget": True, "chosen_step": 0}
    pool = cands + ([(L0, w0, 0)] if keep_w0 else [])
    L, w, c = min(pool, key=lambda t: t[0])  # as printed: argmin over c in [i], w0 not a candidate
    return w, {"iterations": i, "L0": L0, "evals": [(c_, l_) for l_, _, c_ in cands], "chosen_step": c,
               "eta": eta, "stopped_by_budget": stopped_by_budget, "keep_w0": bool(keep_w0)}


def pair_se_model(problem, *, seed: int = 0) -> float:
    """In-silico standard error of a paired Eval difference at w0 (two fresh shot sets, same inputs)."""
    return problem.insilico("pair_se", (int(seed),), lambda: _pair_se(problem, int(seed)))


def _pair_se(problem, seed: int) -> float:
    k = jax.random.fold_in(problem.key, 500 + seed)
    la = per_input_loss(jax.random.fold_in(k, 0), problem.w0, problem.x_ft, problem.y_ft, problem.model,
                        problem.arch, problem.K2)
    lb = per_input_loss(jax.random.fold_in(k, 1), problem.w0, problem.x_ft, problem.y_ft, problem.model,
                        problem.arch, problem.K2)
    return _mean_se(la - lb)[1]


def curvature_model(problem, u, *, K2: int = 8) -> float:
    """u^T Hess_w J_s0(w0) u in silico."""
    from ._directions import hvp_operator
    return problem.insilico("curvature", (u, int(K2)),
                            lambda: float(vdot(u, hvp_operator(problem, K2=int(K2))(u))))


def fit_quadratic(alphas, means, ses, C2_prior=None):
    """Weighted least squares of dJ(a) = a C1 - a^2 C2 / 2 on measured points (a != 0).

    Falls back to C2 = ``C2_prior`` (fitting C1 only) when the fitted curvature is not positive.
    """
    a = np.asarray(alphas, np.float64)
    m = np.asarray(means, np.float64)
    w = 1.0 / np.maximum(np.asarray(ses, np.float64), 1e-12) ** 2
    A = np.stack([a, -0.5 * a * a], axis=1)
    if len(a) >= 2:
        coef = np.linalg.lstsq(A * np.sqrt(w)[:, None], m * np.sqrt(w), rcond=None)[0]
        if coef[1] > 0 or C2_prior is None:
            return float(coef[0]), float(coef[1])
    C2 = float(C2_prior)
    C1 = float(np.sum(w * a * (m + 0.5 * a * a * C2)) / np.sum(w * a * a))
    return C1, C2


def paired_line_search(problem, direction, *, C2=None, se_pair=None, refine: int = 4, z_accept: float = 2.5,
                       confirm_rounds: int | None = None, probe_z: float = 4.0, confirm: bool = True):
    """The repaired GIFT line search along ``direction`` (see module docstring).

    Parameters
    ----------
    problem : Problem
    direction : pytree like the weights (normalised here)
    C2 : u^T H u of the unit direction (default: in silico at s0)
    se_pair : standard error of one paired Eval difference (default: in silico at s0)
    refine : fitted steps after the two probes
    z_accept : sets the overall one-sided level P(Z > z_accept) of the confirmation; each of
        its k looks needs improvement / se > Phi^-1(1 - level / k)
    confirm_rounds : at most this many fresh (w0, candidate) pairs, stopping once accepted
        (default: as many as the budget pays for)
    probe_z : probes at +-a with a^2 C2 / 2 = probe_z * se_pair (a measurable rise)
    confirm : False skips the confirmation (a variant, not GIFT): the best measured point is
        returned whenever its measured improvement is positive

    Returns
    -------
    params, info with the measured curve (alphas, observed dJ and se), the prediction, and
    ``reason``: why w0 was kept or the step taken (see :func:`why`).
    """
    u, u_norm = unit(direction)
    w0 = problem.w0
    with phase("curvature"):
        C2_model = curvature_model(problem, u) if C2 is None else float(C2)
    with phase("pair_se"):
        se_pair = pair_se_model(problem) if se_pair is None else float(se_pair)
    a = math.sqrt(2 * probe_z * se_pair / C2_model) if C2_model > 0 else 0.01 * float(norm(w0))
    info = {"C2_model": C2_model, "se_pair_model": se_pair, "probe": a, "accepted": False}
    if problem.evaluations_left() < 3 - 1e-9:
        info["reason"] = "budget below 3 evaluations: no step measured"
        return w0, info
    l0 = problem.eval_chip(w0)
    alphas, means, ses = [], [], []

    def measure(alpha):
        d = l0 - problem.eval_chip(axpy(alpha, u, w0))
        m, s = _mean_se(d)
        alphas.append(float(alpha))
        means.append(m)
        ses.append(s)

    measure(a)
    measure(-a)
    C1, C2_fit = fit_quadratic(alphas, means, ses, C2_model)
    for _ in range(refine):
        if problem.evaluations_left() < 3 - 1e-9:  # keep two for the confirmation
            break
        C1, C2_fit = fit_quadratic(alphas, means, ses, C2_model)
        span = max(abs(x) for x in alphas)
        alpha = float(np.clip(C1 / C2_fit, -2 * span, 2 * span))  # trust region: at most double the span
        if min(abs(alpha - x) for x in alphas) < 0.05 * span:
            break  # the fit asks for a point already measured
        measure(alpha)
    C1, C2_fit = fit_quadratic(alphas, means, ses, C2_model)
    best = int(np.argmax(means))
    alpha_best = alphas[best]
    info.update({"alphas": alphas, "observed": means, "observed_se": ses, "C1": C1, "C2_fit": C2_fit,
                 "alpha_predicted": C1 / C2_fit if C2_fit > 0 else None, "alpha_best": alpha_best,
                 "direction_norm": float(u_norm)})
    info["predicted_gain"] = float(alpha_best * C1 - 0.5 * alpha_best**2 * C2_fit)
    info["measured_gain"], info["measured_gain_se"] = float(means[best]), float(ses[best])
    info["loss_w0"] = float(np.mean(l0))
    w_best = axpy(alpha_best, u, w0)
    if means[best] <= 0:
        info["reason"] = "no measured step lowered the chip loss"
        return w0, info
    if not confirm:
        info["reason"] = "unconfirmed: the best measured step is taken"
        return w_best, info
    accepted, conf = confirm_on_chip(problem, w_best, z_accept=z_accept, rounds=confirm_rounds)
    info.update(conf, accepted=accepted)
    return (w_best if accepted else w0), info


def confirm_on_chip(problem, w, *, z_accept: float = 2.5, rounds: int | None = None, reference=None):
    """Is ``w`` better than ``reference`` (default w0) on the chip? Fresh paired Evals until convinced.

    Each round measures one Eval_w(K1, K2) of the reference and one of ``w`` on the same inputs
    (fresh shots: 2 units of budget) and looks at the running mean of the paired per-input
    differences; ``w`` is accepted as soon as its improvement exceeds ``z_look`` standard errors,
    ``z_look`` the Bonferroni boundary that keeps the overall one-sided level at
    P(Z > z_accept) over the looks the budget allows (module docstring).

    Returns
    -------
    accepted : bool
    info : dict with ``z_look``, ``confirm_mean``, ``confirm_se``, ``confirm_z``, ``confirm_rounds``
        and ``reason`` (one line)
    """
    ref = problem.w0 if reference is None else reference
    n = int(problem.evaluations_left() // 2)
    if rounds is not None:
        n = min(n, int(rounds))
    z_look = max(z_accept, float(stats.norm.isf(stats.norm.sf(z_accept) / max(n, 1))))
    info = {"z_look": z_look, "confirm_rounds": 0}
    diffs = []
    for _ in range(n):
        if problem.evaluations_left() < 2 - 1e-9:
            break
        diffs.append(problem.eval_chip(ref) - problem.eval_chip(w))
        m, s = _mean_se(np.mean(diffs, axis=0))
        info.update(confirm_mean=m, confirm_se=s, confirm_rounds=len(diffs),
                    confirm_z=m / s if s > 0 else math.copysign(math.inf, m))
        if m > z_look * s:
            info["reason"] = f"accepted: confirmation z = {info['confirm_z']:.2f} > {z_look:.2f}"
            return True, info
    info["reason"] = (f"confirmation not significant: z = {info['confirm_z']:.2f} <= {z_look:.2f} after {len(diffs)} "
                      f"fresh pairs" if diffs else "no budget left for the confirmation")
    return False, info


def confirm_best(problem, candidates, *, z_accept: float = 2.5):
    """The best of several candidate weight sets, if the chip confirms it better than w0.

    Each round measures one Eval_w(K1, K2) of w0 and of every candidate on the same inputs (fresh
    shots); after each round the candidate of the largest mean paired improvement is accepted
    when it exceeds ``z_look`` standard errors, the Bonferroni boundary over the looks the budget
    allows times the candidates (overall one-sided level P(Z > z_accept)).

    Returns
    -------
    index of the accepted candidate or None, info (as :func:`confirm_on_chip`, plus ``chosen``
    and each candidate's last ``confirm_means``)
    """
    k = len(candidates)
    if k == 1:
        ok, info = confirm_on_chip(problem, candidates[0], z_accept=z_accept)
        return (0 if ok else None), dict(info, chosen=0 if ok else None)
    n = int(problem.evaluations_left() // (k + 1))
    z_look = max(z_accept, float(stats.norm.isf(stats.norm.sf(z_accept) / max(n * k, 1))))
    info = {"z_look": z_look, "confirm_rounds": 0, "chosen": None}
    diffs = [[] for _ in candidates]
    for _ in range(n):
        if problem.evaluations_left() < k + 1 - 1e-9:
            break
        l0 = problem.eval_chip(problem.w0)
        for d, w in zip(diffs, candidates):
            d.append(l0 - problem.eval_chip(w))
        stats_ = [_mean_se(np.mean(d, axis=0)) for d in diffs]
        best = int(np.argmax([m for m, _ in stats_]))
        m, s_ = stats_[best]
        info.update(confirm_mean=m, confirm_se=s_, confirm_rounds=len(diffs[0]), confirm_means=[a for a, _ in stats_],
                    confirm_z=m / s_ if s_ > 0 else math.copysign(math.inf, m))
        if m > z_look * s_:
            info["chosen"] = best
            info["reason"] = f"accepted candidate {best}: confirmation z = {info['confirm_z']:.2f} > {z_look:.2f}"
            return best, info
    info["reason"] = (f"confirmation not significant: z = {info['confirm_z']:.2f} <= {z_look:.2f} after "
                      f"{info['confirm_rounds']} fresh rounds" if info["confirm_rounds"] else
                      "no budget left for the confirmation")
    return None, info


def why(method: str, w0, params, info: dict) -> dict | None:
    """Why a line-search method returned what it did, for a report row (``gift_info``).

    Returns
    -------
    dict ``kept_w0`` (the returned weights are w0), ``reason`` (one line), ``confirmation_z``
    (the confirmation's last paired z, NaN when it did not run), ``predicted_gain`` (the
    fitted quadratic's decrease of the chip loss at the best measured step, in loss units;
    NaN when no step was measured), ``predicted_gain_pct`` (the same relative to w0's
    measured chip loss); None for a method without a line search or an Algorithm 1 run.
    """
    kept = all(bool(jax.numpy.all(a == b)) for a, b in zip(jax.tree_util.tree_leaves(w0),
                                                          jax.tree_util.tree_leaves(params)))
    if "chosen_step" in info:  # Algorithm 1 as printed (with or without w0 among its candidates)
        c = info["chosen_step"]
        reason = ("no pair measured (budget)" if info.get("iterations", 0) == 0 else
                  "w0's Eval is the lowest (w0 among the candidates)" if c == 0 else
                  f"step {c} x eta has the lowest Eval" + ("" if info.get("keep_w0") else " (w0 not a candidate)"))
        return {"kept_w0": kept, "reason": reason, "confirmation_z": math.nan, "predicted_gain": math.nan,
                "predicted_gain_pct": math.nan}
    if "accepted" not in info or "probe" not in info:  # not a line search (calibrate, identify-retrain)
        return None
    pg = info.get("predicted_gain", math.nan)
    l0 = info.get("loss_w0", math.nan)
    return {"kept_w0": kept, "reason": info.get("reason", ""), "confirmation_z": float(info.get("confirm_z", math.nan)),
            "predicted_gain": float(pg), "predicted_gain_pct": float(100 * pg / l0) if l0 and math.isfinite(l0)
            else math.nan}
