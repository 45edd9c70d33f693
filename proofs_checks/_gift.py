"""Algorithm 1 (alg:GIFT) as printed and corrected; its stopping rule; Theorem 2
(thm:ft-guarantee); the text's claim that the selection step includes w0 so GIFT never
makes the loss worse."""

from __future__ import annotations

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import sympy as sp
from scipy import stats

import gift_theory as gt

from . import _mc, _onn
from ._record import decide, fmt, hypothesis, level, record, sign_verdict

#: the two stopping rules of the repeat loop: printed "until L+ v L- >= L0" (either side no
#: better), corrected "until L+ ^ L- >= L0" (both sides no better)
STOP_RULES = ("printed", "both")


def make_eval(key, x, y, physics, arch, K2: int):
    """Eval_w(K1, K2) (eq. def:Eval) on a simulated chip: every call draws fresh noise
    (a chip's noise cannot be replayed); returns the K1 per-input losses."""
    counter = itertools.count()

    def eval_fn(w):
        return gt.per_input_loss(jax.random.fold_in(key, next(counter)), w, x, y, physics, arch, K2)

    return eval_fn


def algorithm1(eval_fn, w0, D, eta: float, *, max_iter: int = 50, keep_w0: bool = False, delta: float | None = None,
               stop: str = "printed"):
    """Directional search and selection of alg:GIFT.

    Candidates w^[c,+-] = w0 +- c eta D (the rays from w0; the printed w^[i] of line
    gift:Directional-search read as the previous point of the same ray). ``stop="printed"``
    ends the search at the first i with max(L^[i,+], L^[i,-]) >= L^[0] (line
    gift:Directional-evaluation); ``stop="both"`` at the first i with min(...) >= L^[0].

    Printed selection (``keep_w0=False``, line giftalg:selection): argmin of Eval over
    c in [i] = {1..i}, both signs -- w0 is not a candidate.
    Corrected selection (``keep_w0=True``): w0 is a candidate, and with ``delta`` a
    candidate replaces w0 only if a one-sided paired test (per-input differences of its
    Eval against L^[0]) rejects "not better" at level delta / 2^(c+1) for ray step c and either
    sign, so that the levels sum to at most delta whatever the number of candidates.

    Returns
    -------
    (w_ft, info) with info = {"iterations", "chosen": (c, sign) or (0, 0), "L0": Eval(w0),
    "candidates": [(c, sign, w, Eval(w)) in the order evaluated]}
    """
    if stop not in STOP_RULES:
        raise ValueError(f"stop must be one of {STOP_RULES}")
    flat0, unravel = gt.flatten(w0)
    D = jnp.asarray(D, flat0.dtype)
    L0 = eval_fn(w0)
    cands = []
    i = 0
    while i < max_iter:
        i += 1
        vals = []
        for sign in (+1, -1):
            w = unravel(flat0 + sign * i * eta * D)
            losses = eval_fn(w)
            cands.append((i, sign, w, losses))
            vals.append(float(losses.mean()))
        crit = max(vals) if stop == "printed" else min(vals)
        if crit >= float(L0.mean()):
            break
    best, best_val, chosen = None, math.inf, (0, 0)
    if keep_w0:
        best, best_val = w0, float(L0.mean())
    for c, sign, w, losses in cands:
        val = float(losses.mean())
        if delta is not None:
            d = losses - L0
            se = d.std(ddof=1) / math.sqrt(d.size)
            if not d.mean() + float(stats.norm.isf(delta / 2 ** (c + 1))) * se < 0:
                continue
        if val < best_val:
            best, best_val, chosen = w, val, (c, sign)
    return best, {"iterations": i, "chosen": chosen, "L0": L0, "candidates": cands}


def eval_decisions(info, w0):
    """The comparisons Algorithm 1 (printed stopping rule and selection) made with Eval, as
    (label, w_a, w_b, Eval(w_a), Eval(w_b)) with Eval's answer "mean Eval(w_a) vs mean Eval(w_b)":
    at each step i, the worse side against w0 (the stopping test), then the chosen candidate against
    every other candidate (the selection)."""
    cands = info["candidates"]
    out = []
    for i in range(0, len(cands), 2):
        a, b = cands[i], cands[i + 1]
        worse = a if float(np.mean(a[3])) >= float(np.mean(b[3])) else b
        out.append((f"stop i={worse[0]}: J(w[{worse[0]},{worse[1]:+d}]) - J(w0)", worse[2], w0, worse[3], info["L0"]))
    c, sign = info["chosen"]
    if (c, sign) != (0, 0):
        ch = next(x for x in cands if (x[0], x[1]) == (c, sign))
        for x in cands:
            if (x[0], x[1]) != (c, sign):
                out.append((f"select: J(w[{x[0]},{x[1]:+d}]) - J(w[{c},{sign:+d}])", x[2], ch[2], x[3], ch[3]))
    return out


def _true_difference(key, wa, wb, problem, s, K2):
    phys = problem.physics.replace(s=s)
    with jax.enable_x64(True):
        d = _mc.paired_difference_on_mu(key, wa, wb, problem.x, problem.y, phys, problem.arch, K2=K2)
    return float(d.mean), float(d.se)


def _printed_D(key, st_, K2):
    p = st_.problem
    with jax.enable_x64(True):
        return _mc.d0_printed(key, st_.w0, p.x, p.y, p.physics.replace(s=st_.s0), p.arch, K2=K2)


# --------------------------------------------------------------------------------------
# Theorem 2
# --------------------------------------------------------------------------------------
def theorem2_guarantee(key=None, precise: bool = False) -> dict:
    """thm:ft-guarantee on the tanh ONN at (s0, st) = (0.1, 0.13), where Theorem 1's conditions
    hold: GIFT (printed D^[0], printed Algorithm 1) with eta set without knowledge of st."""
    key = jax.random.PRNGKey(2) if key is None else key
    st_ = _onn.setup(precise)
    p, th1 = st_.problem, st_.theorem1
    kappas = (0.004, 0.002)
    # two tests per eta; the shared Theorem-1 intervals are at ALPHA_CHECK / 4 (_onn.HYPOTHESIS_CONFIDENCE),
    # which two slots of ALPHA_CHECK / 6 cover: 4/6 + 1/4 < 1
    lev = level(2 + 2 * len(kappas))
    D = _printed_D(jax.random.fold_in(key, 0), st_, K2=64 if precise else 32)
    Dm = np.asarray(D.mean)
    Dn = float(np.linalg.norm(Dm))
    w0n = float(np.linalg.norm(np.asarray(gt.flatten(st_.w0)[0])))
    v = np.asarray(th1["v_bar"])
    # the proof's range of steps: alpha in (0, C1/C2) along -v; a candidate w0 + c eta D is w0 - alpha v
    # with alpha = -c eta (D.v)/||v||^2 (D^[0] estimates -(s0/2) v, so the + ray is the descent one)
    C1, C2 = th1["C1"], th1["C2_at_alpha0"]
    alpha_max_lo = C1["lo"] / C2["hi"] if C1["lo"] > 0 and C2["hi"] > 0 else 0.0
    rows, tests = [], []
    K2e = 4096 if precise else 2048            # "K1, K2 sufficiently large": Eval must resolve the change (K_large)
    for j, kappa in enumerate(kappas):
        eta = kappa * w0n / Dn                      # a step of kappa ||w0||: no oracle quantity at st
        ev = make_eval(jax.random.fold_in(key, 10 + j), p.x, p.y, p.physics.replace(s=st_.st), p.arch, K2=K2e)
        with jax.enable_x64(True):
            w_ft, info = algorithm1(ev, st_.w0, Dm, eta)
        c, sign = info["chosen"]
        alpha = abs(c * eta * float(Dm @ v) / float(v @ v))
        small = 0 < alpha < alpha_max_lo
        diff, se = _true_difference(jax.random.fold_in(key, 20 + j), w_ft, st_.w0, p, st_.st, K2=256 if precise else 128)
        vd, z = sign_verdict(diff, se, "negative", confidence=lev.confidence)
        # "K1, K2 sufficiently large": every comparison Algorithm 1 made with Eval (fresh draws each call, as
        # on a chip) agrees with J_st and resolves its true difference: |J_st(a) - J_st(b)| > z1 * se of
        # Eval(a) - Eval(b)
        dec = eval_decisions(info, st_.w0)
        res_d = []
        for n_d, (label, wa, wb, la, lb) in enumerate(dec):
            t_d, _ = _true_difference(jax.random.fold_in(key, 100 * (j + 1) + n_d), wa, wb, p, st_.st, K2=64)
            e_d = np.asarray(la) - np.asarray(lb)
            se_e = float(e_d.std(ddof=1) / math.sqrt(e_d.size))
            res_d.append((label, t_d, float(e_d.mean()), se_e,
                          abs(t_d) > lev.z1 * se_e and np.sign(t_d) == np.sign(e_d.mean())))
        resolved = all(r_[-1] for r_ in res_d)
        tests.append((small, vd, resolved))
        rows.append(f"eta = {kappa:g} ||w0||/||D|| = {fmt(eta)}: stopped at i = {info['iterations']}, chose c = {c} "
                    f"sign {sign:+d}, i.e. alpha = {fmt(alpha)} along -v ({'inside' if small else 'outside'} the "
                    f"proof's range (0, C1/C2 >= {fmt(alpha_max_lo)})); J_st(w_ft) - J_st(w0) = {fmt(diff)} +- "
                    f"{fmt(se)} (z = {z:.1f}: {vd}); Eval's comparisons (true difference vs Eval's difference "
                    f"+- se): " + ", ".join(f"{lab}: {fmt(td)} vs {fmt(ed)} +- {fmt(se_)}"
                                            f"{'' if ok_ else ' NOT resolved'}" for lab, td, ed, se_, ok_ in res_d))
    inside = [vd for small, vd, _ in tests if small]
    resolved_inside = [res for small, _, res in tests if small]
    hyp_th1 = _onn.hypotheses_of_theorem1(th1)
    hyps_ok = all(h["verified"] is True for h in hyp_th1 if h["needed_for_refutation"])
    K_ok = bool(resolved_inside) and all(resolved_inside)
    ok = hyps_ok and bool(inside) and K_ok
    verdict = decide(fails=ok and any(v_ == "fails" for v_ in inside), holds=ok and all(v_ == "holds" for v_ in inside))
    hyps = hyp_th1 + [hypothesis("eta_small", "eta sufficiently small (the proof: the step lies in Table "
                                 "alpha-values' range)", bool(inside), f"{len(inside)} of {len(kappas)} eta inside "
                                 f"(0, C1/C2) at the confidence"),
                      hypothesis("K_large", "K1, K2 sufficiently large", K_ok,
                                 f"K1 = all {p.x.shape[0]} points of mu, K2 = {K2e} draws per input in Eval, D^[0] "
                                 f"from {64 if precise else 32} draws per input: at every eta inside the range, every "
                                 f"comparison Algorithm 1 made with Eval has the sign of the true difference, which "
                                 f"exceeds {lev.z1:.2f} standard errors of Eval's difference")]
    return record(
        "theorem2_guarantee",
        "thm:ft-guarantee, eq. claim thoerem GIFT 2: under ass:Nonempty-minimizer-sets and ass:Laplacian-properties, "
        "for small eta and large K1, K2, J_st(w_ft) < J_st(w0) for w_ft = GIFT(s0; eta, K1, K2) (Algorithm 1 with "
        "the printed D^[0])",
        verdict,
        f"tanh ONN {p.arch}, n = {p.x.shape[0]} teacher points, s0 = {st_.s0:g}, st = {st_.st:g} (Theorem 1's printed "
        f"/ corrected condition: {th1['printed_condition']} / {th1['corrected_condition']} at the confidence, as in "
        f"theorem1_conclusion), w0 trained at s0, printed D^[0]; eta chosen as fractions of "
        f"||w0||/||D^[0]|| (no quantity at st): " + "; ".join(rows)
        + f". Paired fresh-draw tests; {lev.text()}. The printed D^[0] estimates -(s0/2) d/ds grad J (d0_limit), a "
          f"rescaling the two-sided search absorbs",
        correction=None if verdict != "fails" else "see gift_never_worse and algorithm1_stopping_rule",
        counterexample=None if verdict != "fails" else {"rows": rows}, hypotheses=hyps)


# --------------------------------------------------------------------------------------
# the selection step: "GIFT never makes the loss worse"
# --------------------------------------------------------------------------------------
def _clopper_pearson(k, n, conf):
    lo = stats.beta.ppf((1 - conf) / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - (1 - conf) / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def gift_never_worse(key=None, precise: bool = False) -> dict:
    """The text: the selection step includes w0, so GIFT never makes the loss worse.
    Tested on the printed Algorithm 1 with st = s0 (no misspecification: every step away
    from the critical point w0 is worse), then the corrected selection."""
    key = jax.random.PRNGKey(3) if key is None else key
    lev = level(2)
    st_ = _onn.setup(precise)
    p, s0 = st_.problem, st_.s0
    phys0 = p.physics.replace(s=s0)
    D = _printed_D(jax.random.fold_in(key, 0), st_, K2=32)
    flat0, _ = gt.flatten(st_.w0)
    eta = 0.05 * float(jnp.linalg.norm(flat0)) / float(np.linalg.norm(D.mean))
    K2e = 16
    ev = make_eval(jax.random.fold_in(key, 1), p.x, p.y, phys0, p.arch, K2=K2e)
    with jax.enable_x64(True):
        w_ft, info = algorithm1(ev, st_.w0, D.mean, eta)
    diff, se = _true_difference(jax.random.fold_in(key, 2), w_ft, st_.w0, p, s0, K2=64)
    worse_v, z = sign_verdict(diff, se, "positive", confidence=lev.confidence)
    # corrected selection: w0 kept, paired one-sided tests at levels delta / 2^(c+1); replicate runs
    delta = 0.1
    R = 240 if precise else 120
    worse, accepted, truth = 0, 0, {}
    for r in range(R):
        ev = make_eval(jax.random.fold_in(key, 100 + r), p.x, p.y, phys0, p.arch, K2=K2e)
        with jax.enable_x64(True):
            w_c, inf = algorithm1(ev, st_.w0, D.mean, eta, keep_w0=True, delta=delta)
        if inf["chosen"] != (0, 0):
            accepted += 1
            if inf["chosen"] not in truth:
                truth[inf["chosen"]] = _true_difference(jax.random.fold_in(key, 7), w_c, st_.w0, p, s0, K2=64)
            worse += truth[inf["chosen"]][0] > 0
    _, hi = _clopper_pearson(worse, R, 1 - 2 * lev.alpha)        # one-sided upper bound at lev.alpha
    lo_strict, _ = _clopper_pearson(worse, R, 1 - 2 * lev.alpha)
    corrected_v = decide(fails=lo_strict > delta, holds=hi <= delta)
    # "never worse" is universal: one significantly worse run refutes it
    verdict = decide(fails=worse_v == "holds")
    correction = None
    if corrected_v == "holds":
        correction = (f"keep w0 among the candidates and let a candidate w0 +- c eta D replace w0 only if a one-sided "
                      f"paired test of its Eval against L^[0] (per-input differences) rejects 'not better' at level "
                      f"delta / 2^(c+1); then P(J_st(w_ft) > J_st(w0)) <= delta: in {R} runs at st = s0 with delta = "
                      f"{delta:g}, {worse} returned a worse point (one-sided Clopper-Pearson upper bound {fmt(hi)} <= "
                      f"delta at level {lev.alpha:.2g})")
    hyps = [hypothesis("w0_critical", "w0 a critical point of J_s0 (the text's setting)",
                       next(h["verified"] for h in st_.theorem1["hypotheses"] if h["name"] == "w0_critical"),
                       "from the Theorem-1 check of the same w0"),
            hypothesis("st_equals_s0", "st = s0 lies outside Theorems 1-2 (0 < |st - s0|), not outside the text's "
                       "claim, which has no condition", True, "the claim is universal", needed_for_refutation=False)]
    return record(
        "gift_never_worse",
        "alg:GIFT, line giftalg:selection (argmin over c in [i], w0 not a candidate) and the text's claim that the "
        "selection includes w0 so that GIFT never makes J_st worse",
        verdict,
        f"printed Algorithm 1 at st = s0 = {s0:g} (w0 critical, eta ||D|| = 5% of ||w0||): stopped at i = "
        f"{info['iterations']}, returned c={info['chosen'][0]} sign={info['chosen'][1]:+d} with J_st(w_ft) - J_st(w0) = "
        f"{fmt(diff)} +- {fmt(se)} (z = {z:.1f}, one-sided); corrected selection: {accepted}/{R} runs replaced w0, "
        f"{worse}/{R} worse (one-sided upper bound {fmt(hi)} against delta = {delta:g}); {lev.text()}",
        correction=correction,
        counterexample=None if verdict != "fails" else {"s0": s0, "st": s0, "eta": eta, "difference": diff, "se": se,
                                                         "chosen": list(info["chosen"])},
        hypotheses=hyps)


# --------------------------------------------------------------------------------------
# the stopping rule of the directional search
# --------------------------------------------------------------------------------------
def stopping_rule_exact():
    """For a line function f(c) = a c + b c^2 (b > 0): the printed rule stops at i = 1 for every
    slope a, since max(f(eta), f(-eta)) >= (f(eta) + f(-eta))/2 = b eta^2 > 0 = f(0), while the
    minimiser along the line is c* = -a/(2 b eta) steps away. Then :func:`algorithm1` itself on
    the deterministic line f(c) = -c + c^2/26 (c* = 13): printed and 'both sides' rules."""
    a = sp.Symbol("a", real=True, nonzero=True)
    b, eta = sp.symbols("b eta", positive=True)
    c = sp.Symbol("c", real=True)
    f = lambda t: a * t + b * t ** 2
    avg = sp.simplify((f(eta) + f(-eta)) / 2 - f(0))
    cstar = sp.solve(sp.diff(f(c * eta), c), c)[0]
    cross = sp.solve(sp.Eq(f(c * eta), 0), c)

    def line_eval(w):        # a deterministic chip: J along the line, the same value for every input
        t = float(w[0].W[0, 0])
        return np.full(8, -t + t * t / 26.0)

    w0 = (gt.Layer(jnp.zeros((1, 1)), jnp.zeros((1,))),)
    D = np.array([1.0, 0.0])
    _, info_p = algorithm1(line_eval, w0, D, 1.0)
    _, info_b = algorithm1(line_eval, w0, D, 1.0, stop="both")
    keep = lambda info: {"iterations": info["iterations"], "chosen": info["chosen"]}
    return {"avg_minus_f0": avg, "c_star": cstar, "descent_side_crossing": [str(x) for x in cross],
            "printed": keep(info_p), "both": keep(info_b)}


def algorithm1_stopping_rule(key=None, precise: bool = False) -> dict:
    key = jax.random.PRNGKey(19) if key is None else key
    lev = level(3)          # the shared Theorem-1 intervals, the stop-index count, the paired comparison
    ex = stopping_rule_exact()
    exact_fails = bool(ex["avg_minus_f0"].is_positive)
    st_ = _onn.setup(precise)
    p, th1 = st_.problem, st_.theorem1
    D = _printed_D(jax.random.fold_in(key, 0), st_, K2=32)
    Dm = np.asarray(D.mean)
    eta = 0.0005 * float(np.linalg.norm(np.asarray(gt.flatten(st_.w0)[0]))) / float(np.linalg.norm(Dm))
    v = np.asarray(th1["v_bar"])
    step_alpha = abs(eta * float(Dm @ v) / float(v @ v))
    c_star = th1["alpha"] / step_alpha                  # the quadratic model's optimum, in ray steps
    R = 16 if precise else 8
    K2e = 128
    stops, diffs = [], []
    for r in range(R):
        kr = jax.random.fold_in(key, 100 + r)
        with jax.enable_x64(True):
            w_p, ip = algorithm1(make_eval(jax.random.fold_in(kr, 0), p.x, p.y, p.physics.replace(s=st_.st), p.arch,
                                           K2=K2e), st_.w0, Dm, eta)
            w_b, ib = algorithm1(make_eval(jax.random.fold_in(kr, 1), p.x, p.y, p.physics.replace(s=st_.st), p.arch,
                                           K2=K2e), st_.w0, Dm, eta, stop="both")
        stops.append((ip["iterations"], ib["iterations"], ib["chosen"][0]))
        diffs.append(_true_difference(jax.random.fold_in(kr, 2), w_b, w_p, p, st_.st, K2=64)[0])
    stops = np.array(stops)
    d = np.array(diffs)
    better, z = sign_verdict(float(d.mean()), float(d.std(ddof=1) / math.sqrt(R)), "negative",
                             confidence=lev.confidence)
    one_step = int(np.sum(stops[:, 0] == 1))
    line_ok = (ex["printed"]["iterations"], ex["printed"]["chosen"]) == (1, (1, 1)) and ex["both"]["chosen"] == (13, 1)
    verdict = decide(fails=exact_fails and ex["printed"]["iterations"] == 1)
    corrected_ok = line_ok          # verified exactly; the ONN comparison is reported, not used
    b_sym = next(x for x in ex["avg_minus_f0"].free_symbols if x.name == "b")
    eta_sym = next(x for x in ex["avg_minus_f0"].free_symbols if x.name == "eta")
    C2 = th1["C2_at_alpha0"]
    hyps = [hypothesis("require", "Require of alg:GIFT: s0 > 0, eta > 0, K1, K2 >= 1", bool(
                           eta_sym.is_positive and st_.s0 > 0 and eta > 0 and p.x.shape[0] >= 1 and K2e >= 1),
                       f"exact line: eta a positive symbol; ONN: s0 = {st_.s0:g}, eta = {fmt(eta)}, K1 = "
                       f"{p.x.shape[0]}, K2 = {K2e}"),
            hypothesis("convex_line", "J_st convex along the ray near w0 (w0 a minimiser of J_s0 and st near s0)",
                       bool(b_sym.is_positive), "exact line f(c) = a c + b c^2 with b a positive symbol, a any "
                       "nonzero real: every case at once"),
            hypothesis("onn: w0_critical", "w0 an approximate minimiser of J_s0 (Initialization)",
                       next(h["verified"] for h in th1["hypotheses"] if h["name"] == "w0_critical"),
                       "from the Theorem-1 check of the same w0; the ONN instance illustrates, the verdict rests on "
                       "the exact line", needed_for_refutation=False),
            hypothesis("onn: convex_ray", "J_st convex along -v at w0 (C2 > 0)", C2["lo"] > 0,
                       f"C2 at alpha -> 0 in [{fmt(C2['lo'])}, {fmt(C2['hi'])}] (Theorem-1 intervals)",
                       needed_for_refutation=False)]
    evidence = (f"exact (sympy): for any line function f(c) = a c + b c^2 with b > 0, max(f(eta), f(-eta)) - f(0) >= "
                f"(f(eta) + f(-eta))/2 - f(0) = {ex['avg_minus_f0']} > 0 for every slope a, so 'until L+ v L- >= L0' "
                f"stops at i = 1 although the line minimum is at c* = {ex['c_star']} steps; the descent side stays "
                f"below L0 up to c = {ex['descent_side_crossing']}; algorithm1 on the line f(c) = -c + c^2/26 (c* = 13): "
                f"printed rule {ex['printed']}, 'both sides' rule {ex['both']}. tanh ONN at s0 = {st_.s0:g}, st = {st_.st:g}, eta "
                f"= 0.05% of ||w0||/||D^[0]||, Eval with K2 = {K2e} (quadratic model: c* about {fmt(c_star)} steps): the printed rule stopped "
                f"at i = 1 in {one_step}/{R} runs (median stop {float(np.median(stops[:, 0])):g}); the rule 'until L+ "
                f"^ L- >= L0' stopped at median i = {float(np.median(stops[:, 1])):g} and chose median c = "
                f"{float(np.median(stops[:, 2])):g}; J_st(corrected) - J_st(printed) = {fmt(float(d.mean()))} +- "
                f"{fmt(float(d.std(ddof=1) / math.sqrt(R)))} (paired, fresh draws; z = {z:.1f}: {better}). {lev.text()}")
    correction = None
    if corrected_ok:
        correction = ("stop when both directions are no better: 'until L^[i,+] ^ L^[i,-] >= L^[0]' (then select the "
                      "argmin, keeping w0 as in gift_never_worse); on a convex line the search then reaches 2|c*| and "
                      f"returns the candidate nearest c* (verified exactly with algorithm1 on f(c) = -c + c^2/26: "
                      f"chose c = {ex['both']['chosen'][0]}); on the ONN the comparison with the printed rule is "
                      f"reported in the evidence (z = {z:.1f}: {better}) and not used to verify the correction")
    return record(
        "algorithm1_stopping_rule",
        "alg:GIFT, lines gift:Directional-search / gift:Directional-evaluation: the repeat loop performs an in situ "
        "search along +-D^[0] ('along which an in situ search is then performed'), stopping 'until L^[i,+] v "
        "L^[i,-] >= L^[0]'",
        verdict, evidence, correction,
        counterexample=None if verdict != "fails" else {
            "line_function": "f(c) = a c + b c^2, b > 0", "max_side_minus_f0_at_i1": str(ex["avg_minus_f0"]) + " (>= )",
            "c_star": str(ex["c_star"]), "onn_stops_at_1": f"{one_step}/{R}", "onn_c_star": c_star},
        hypotheses=hyps)
