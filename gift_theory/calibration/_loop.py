"""``calibrate``: measure the chip, read off what it realises, program what makes it realise the
trained network, measure again, and confirm on the chip before returning.

The loop (docs/hardware.md, "Calibrating a chip"; docs/reference.md §7)::

    target <- w0                                   the network to realise (an *effective* one)
    p <- w0                                        what is programmed
    repeat while the budget lasts (keeping the confirmation's share):
        measure p on the chip (inputs x shots, taps where the chip has them)
        fit each layer's realised map (W_eff, b_eff) (:func:`~gift_theory.calibration.fit_layers`)
        compare with the last round: an entry whose realised value did not follow a programmed
            change is stuck (a stuck weight; a dead neuron is a row and bias stuck) and pinned at
            its realised value; the rows' gains are the secants realised / programmed change
        if something new is pinned, or the noise level read off the shots differs from s0:
            retrain the target in silico under the identified device: the pinned entries held at
            their realised values, the noise at its identified level (warm start from the target)
        p <- p + (target - realised) / gain         (closed loop: each round's residual map is the
                                                     next round's correction; pinned entries keep w0)
    confirm p against w0 on the chip (paired Evals on fresh shots, the line search's sequential
    rule); return p if it is significantly better, else w0

Without taps only the output layer is read (its regressor the model's hidden layers as
programmed) and corrected; the hidden layers' maps, stuck weights and dead neurons are not
identified, and the report says so. The first round's measurement then also goes to the lab's
diagnosis (every effect but per-device offsets); when it names a model the data do not reject,
w0 retrained under it is a second candidate; after a few rounds of the output's closed loop,
the rest of the budget trains its result further on the chip's own outputs (``pat-identified``
from it, the model at the noise level read off the shots) for a third. The confirmation measures
every candidate against w0 on the same inputs and returns the best if the chip finds it
significantly better than w0.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from .. import _random
from .._params import Layer, params32
from .._phases import phase
from ..effects import awgn
from ._fit import fit_layers


#: each activation's derivative
_SLOPES = {"tanh": lambda z: 1.0 - np.tanh(z) ** 2, "identity": lambda z: np.ones_like(z),
           "sigmoid": lambda z: (lambda f: f * (1.0 - f))(1.0 / (1.0 + np.exp(-z))), "sin": np.cos}


def _np(params):
    return [(np.array(W, np.float64), np.array(b, np.float64)) for W, b in params]


def _layers32(params):
    return params32(tuple(Layer(W, b) for W, b in params))


def _pinned(fixed, values, like):
    from ..training import Pinned
    mask = tuple(Layer(jnp.asarray(mW), jnp.asarray(mb)) for mW, mb in fixed)
    val = tuple(Layer(jnp.asarray(vW, jnp.float32), jnp.asarray(vb, jnp.float32)) for vW, vb in values)
    return Pinned(mask, val)


def _retrain_target(problem, start, fixed, values, physics, seed: int):
    """The target retrained in silico under the noise ``physics`` with the pinned entries held at their values."""
    from ..finetune._rivals import RETRAIN
    from ..training import train

    key = jax.random.fold_in(problem.key, 7100 + seed)
    out = train(key, problem.arch, problem.x, problem.y, physics, RETRAIN, params=_layers32(start),
                pinned=_pinned(fixed, values, start))
    return _np(out)


#: the mechanism classes (docs/reference.md §6) a chip's noise is read in: what is not a fixed map
NOISE_CLASSES = ("noise_level", "noise_law", "input_dependent_noise", "gain_fluctuation", "correlated_noise",
                 "readout_nonlinearity", "time_drift", "memory")


def noise_physics(key, meas, effects=(), *, s: float | None = None, alpha: float = 0.01):
    """The noise of the chip ``meas`` measured, read by the measurement lab with the realised maps as
    the weights (so a fixed map is not read as noise): the ``effects`` named, fitted; else awgn at
    the level ``s`` read off the shots when it passes the lab's test (p >= ``alpha``); else the
    diagnosis' model over the noise-like classes and the loaded plugins of those classes (its
    best passing model when the awgn model fails, else awgn at its fitted level).

    Returns
    -------
    physics, info (``physics``, ``used``, ``baseline_p``)
    """
    from ..effects import REGISTRY
    from ..lab import default_candidates, diagnose, fit_effects
    from ..lab import fitted_as_offsets

    if effects:
        ph = fit_effects(key, meas, list(effects)).after.physics
        return ph, {"physics": ph.describe(), "used": "the effects named"}
    if s is not None:  # the diagnosis only where awgn at the shots' level does not fit
        from ..lab import Model, compare

        c = compare(jax.random.fold_in(key, 1), Model(awgn(s)), meas)
        if c.p_value >= alpha:
            ph = awgn(s)
            return ph, {"physics": ph.describe(), "baseline_p": c.p_value, "used": "awgn (it fits)"}
    cands = [c for c in default_candidates(meas)
             if REGISTRY[c].mechanism in NOISE_CLASSES and not fitted_as_offsets(c)]
    d = diagnose(key, meas, candidates=cands)
    top = d.ranking[0] if d.ranking else None
    use = d.missing_effect_detected and top is not None and top.status == "passes"
    ph = top.model.physics if use else d.baseline.physics
    return ph, {"physics": ph.describe(), "baseline_p": d.baseline_comparison.p_value,
                "used": "the diagnosis' model" if use else
                ("awgn (the best noise model fails its test)" if d.missing_effect_detected else "awgn (it fits)")}


def _row_gain(W_eff, W):
    num = np.sum(W_eff * W, axis=1)
    den = np.sum(W * W, axis=1)
    return np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)


def calibrate(problem, *, inputs: int = 256, shots: int = 8, rounds: int | None = None, reserve: float = 4.0,
              z_accept: float = 2.5, stuck_z: float = 5.0, stuck_ratio: float = 0.25, gain_clip=(0.4, 2.5),
              noise_tolerance: float = 0.1, retrain: bool = True, ridge: float = 0.01, no_taps_rounds: int = 3,
              noise_model: bool = True, effects=()):
    """Calibrate the chip of ``problem`` to realise w0 (module docstring).

    Parameters
    ----------
    problem : :class:`~gift_theory.finetune.Problem` (its chip: any Chip; taps used where it has them)
    inputs, shots : each round measures at most ``inputs`` fine-tuning inputs ``shots`` times (fewer
        inputs, down to 32, when the budget would otherwise pay for fewer than four rounds)
    rounds : at most this many measure-and-correct rounds (default: as many as the budget pays for)
    reserve : chip evaluations kept for the confirmation (two per paired round)
    z_accept : the confirmation's overall one-sided level P(Z > z_accept)
    stuck_z, stuck_ratio : an entry is stuck when its programmed value moved by more than
        ``stuck_z`` standard errors of the realised change and its realised value followed by less
        than ``stuck_ratio`` of the row's gain
    gain_clip : the range a row's gain estimate is held in (a step never more than 1/0.4 of the residual)
    noise_tolerance : retrain under the identified noise level when it differs from s0 by more than this share
    noise_model : with taps, read the noise beyond its level from the first round (the lab's diagnosis
        over the noise-like classes, plugins included, on the realised maps: :func:`noise_physics`) and
        retrain under it when it names more than awgn
    effects : the effects to fit as the noise instead of the diagnosis' choice
    retrain : False never retrains (pre-compensation only)
    ridge : a correction acts on the directions the layer's inputs span; ``ridge`` (relative to their
        mean second moment) sets how weakly spanned a direction may be (:meth:`_LayerState.correct`)
    no_taps_rounds : without taps, the rounds of the output's closed loop (the rest of the budget
        goes to physics-aware training from its result)

    Returns
    -------
    params, info (``identified``: what each layer showed; ``rounds``: each round's residual;
    ``accepted``/``reason``: the confirmation; ``not_identified``: what the chip's data could not show)
    """
    w0 = _np(problem.w0)
    L = len(w0)
    slope = _SLOPES[problem.arch.activation]
    spend = (problem.evaluations_left() - reserve) * problem.unit_shots
    n = int(min(inputs, problem.K1, max(32, spend // (4 * int(shots)))))
    max_rounds = None if rounds is None else int(rounds)
    order = _random.permutation(jax.random.fold_in(problem.key, 7000), problem.K1)  # jax.random.permutation's
    idx_cal = np.sort(order[:n])
    x_cal, y_cal = problem.x_ft[idx_cal], np.asarray(problem.y_ft[idx_cal], np.float64)
    cost = n * int(shots) / problem.unit_shots
    target = [(W.copy(), b.copy()) for W, b in w0]
    prog = [(W.copy(), b.copy()) for W, b in w0]
    lays = [_LayerState(W, b) for W, b in w0]
    prev, s_hat, taps, retrained, history, first = None, None, None, 0, [], {}
    noise, info_noise = None, None
    measured = []  # (chip loss on the round's shots, its standard error, the weights measured)
    for k in range(10 ** 6 if max_rounds is None else max_rounds):
        if problem.evaluations_left() < cost + reserve - 1e-9:
            break
        if taps is False and k >= no_taps_rounds:  # the output's map converges in a few rounds
            break
        with phase("chip"):
            meas = problem.chip.measure(_layers32(prog), x_cal, int(shots), taps=True)
        taps = meas.has_taps
        if k == 0:
            first_meas = meas
        # the round's shots price the programmed weights on the chip at no extra cost: the loss
        # E|y - y_target|^2 each round reached, so that a loop that wanders off is seen
        per_input = np.mean(np.sum((np.asarray(meas.y, np.float64) - y_cal[:, None, :]) ** 2, axis=-1), axis=1)
        measured.append((float(per_input.mean()), float(per_input.std(ddof=1) / math.sqrt(n)),
                         [(W.copy(), b.copy()) for W, b in prog]))
        if len(measured) >= 3 and measured[-1][0] > measured[-2][0] > measured[-3][0]:
            break  # the chip's loss rose twice running: the corrections no longer help; the budget goes to the confirmation
        with phase("calibration fit"):
            fits = fit_layers(meas, s=s_hat)
        s_hat = float(np.median([f.s for f in fits]))
        new_pins = 0
        for f in fits:
            if prev is None:
                lays[f.layer - 1].first(f, gain_clip, f.layer == L)
                first[f.layer] = f
            else:
                new_pins += lays[f.layer - 1].secant(f, prev[f.layer], stuck_z, stuck_ratio, gain_clip)
        if prev is None and taps and retrain and noise_model:
            with phase("calibration noise"):  # the noise beyond its level: law, signal-dependent parts
                realised = dataclasses.replace(meas, params=tuple(Layer(f.W, f.b) for f in fits))
                noise, info_noise = noise_physics(jax.random.fold_in(problem.key, 7300), realised, effects, s=s_hat)
        if noise is None or noise.names == ("awgn",):
            mismatch = abs(s_hat / problem.s0 - 1.0) > noise_tolerance
            physics = awgn(s_hat if mismatch else problem.s0)
        else:
            mismatch, physics = True, noise
        if retrain and (new_pins or (prev is None and mismatch)):
            with phase("calibration retrain"):
                start = [st.pinned_start(W, b) for (W, b), st in zip(target, lays)]
                target = _retrain_target(problem, start, [st.fixed for st in lays], [st.values for st in lays],
                                         physics, k)
            retrained += 1
            for st in lays:
                st.best = None  # a new target: the residuals before it do not compare
        row = {"round": k, "inputs": n, "shots": int(shots), "noise_level": s_hat, "pinned_new": new_pins,
               "chip_loss": measured[-1][0], "chip_loss_se": measured[-1][1], "layers": {}}
        for f in fits:
            st = lays[f.layer - 1]
            prog[f.layer - 1], row["layers"][str(f.layer)] = st.correct(f, target[f.layer - 1], w0[f.layer - 1], ridge,
                                                                         slope)
        if not taps:  # the hidden layers are not read: programmed as the target
            prog[:L - 1] = [(W.copy(), b.copy()) for W, b in target[:L - 1]]
        history.append(row)
        prev = {f.layer: f for f in fits}
    info = {"rounds": history, "taps": taps, "retrained": retrained, "noise_level": s_hat, "noise": info_noise,
            "identified": _identified(first, lays, L),
            "not_identified": [] if taps else
            ["the hidden layers' maps, stuck weights and dead neurons (no taps: only the output map is read)"]}
    if not history:
        info.update(accepted=False, reason="budget below one round and the confirmation: nothing measured")
        return problem.w0, info
    return _confirmed(problem, prog, measured, taps, retrain, first_meas, s_hat, z_accept, info)


def _confirmed(problem, prog, measured, taps, retrain, first_meas, s_hat, z_accept, info):
    """The chip chooses, by the confirmation (:func:`~gift_theory.finetune._linesearch.confirm_best`),
    between the calibrated weights, a round's that measured lower, and without taps the weights
    retrained under the diagnosis' model and trained further on the chip's outputs; w0 when none
    is confirmed. Returns (params, info)."""
    from ..finetune._linesearch import confirm_best
    candidates = [_layers32(prog)]
    names = ["the calibrated weights"]
    best = 1 + int(np.argmin([m[0] for m in measured[1:]])) if len(measured) > 1 else None
    if best is not None and best < len(measured) - 1 and measured[best][0] < measured[-1][0]:
        # a round before the last measured lower: the corrections after it went astray (a chip whose
        # map is not the row-wise response the loop models); the chip chooses between the two
        candidates.append(_layers32(measured[best][2]))
        names.append(f"the weights of round {best} (the lowest loss the rounds measured)")
    if not taps and retrain:
        # the output alone cannot show the hidden layers' maps: the lab's diagnosis of the first round
        # (every effect but per-device offsets, as identify-retrain) may name a global one -- a layer's
        # gain, an activation's slope -- that retraining under can absorb; the chip chooses between them
        from ..finetune._rivals import physics_of, retrain as _retrain
        with phase("calibration diagnosis"):
            physics, pinfo = physics_of(jax.random.fold_in(problem.key, 7200), first_meas)
        info["diagnosis"] = pinfo
        if pinfo["used"] == "the top-ranked model":
            candidates.append(_retrain(problem, physics))
            names.append("the weights retrained under the diagnosis' model")
        # what the output cannot show, the chip's own outputs can still steer: physics-aware
        # training from the calibrated weights with the rest of the budget (the model at the noise
        # level read off the shots), the confirmation's share kept
        from ..finetune._rivals import pat
        keep = 2.0 * (len(candidates) + 2)
        if problem.evaluations_left() > keep + 1:
            with phase("calibration pat"):
                w_pat, _ = pat(problem, noise="identified", level=s_hat, start=candidates[0], reserve=keep)
            candidates.append(w_pat)
            names.append("the calibrated weights trained further on the chip's outputs (pat-identified)")
    with phase("chip"):
        chosen, conf = confirm_best(problem, candidates, z_accept=z_accept)
    info.update(conf, accepted=chosen is not None, returned="w0" if chosen is None else names[chosen])
    return (problem.w0 if chosen is None else candidates[chosen]), info


class _LayerState:
    """One layer's calibration state across rounds: pinned entries, the rows' gains, the trust region.

    ``fixed``/``values``: (W, b) masks of pinned entries and their realised values; ``flagged``:
    entries that did not follow their programmed change in the last round (pinned when they fail
    twice running: a mesh mixes entries, so one round's non-response can be another entry's
    change cancelling it); ``gain_W``/``gain_b``: per row, realised over programmed change;
    ``step``: the share of the residual the next correction takes (halved when a round's residual
    came out worse than the best so far, the correction then restarting from the best);
    ``best``: (chi2, programmed, residual / gain) of the best round under the current target.
    """

    def __init__(self, W, b):
        d = W.shape[0]
        self.fixed = (np.zeros(W.shape, bool), np.zeros(b.shape, bool))
        self.values = (np.zeros(W.shape), np.zeros(b.shape))
        self.flagged = (np.zeros(W.shape, bool), np.zeros(b.shape, bool))
        self.gain_W, self.gain_b = np.ones(d), np.ones(d)
        self.step, self.best = 1.0, None
        self.dead_flag = np.zeros(d, bool)

    def pinned_start(self, W, b):
        return np.where(self.fixed[0], self.values[0], W), np.where(self.fixed[1], self.values[1], b)

    def first(self, f, gain_clip, output: bool):
        self.gain_W = np.clip(_row_gain(f.W, f.W_prog), *gain_clip)
        if output:  # a detector reads z_L, bias included (the secants correct this where it is wrong)
            self.gain_b = self.gain_W.copy()

    def secant(self, f, old, stuck_z, stuck_ratio, gain_clip) -> int:
        """Compare this round's fit ``f`` with the last one ``old``: pin what is stuck, update the gains."""
        pins = 0
        new_flags = []
        for j, (dp, de, se, gain) in enumerate((
                (f.W_prog - old.W_prog, f.W - old.W, np.sqrt(f.W_se ** 2 + old.W_se ** 2), self.gain_W[:, None]),
                (f.b_prog - old.b_prog, f.b - old.b, np.sqrt(f.b_se ** 2 + old.b_se ** 2), self.gain_b))):
            moved = np.abs(dp) > stuck_z * se
            flag = moved & (np.abs(de) < stuck_ratio * np.abs(gain) * np.abs(dp)) & ~self.fixed[j]
            pin = flag & self.flagged[j]
            self.fixed[j][pin] = True
            self.values[j][pin] = (f.W, f.b)[j][pin]
            pins += int(pin.sum())
            new_flags.append(flag & ~pin)
            use = moved & ~self.fixed[j] & ~flag
            if j == 0:  # the rows' gains: realised over programmed change where the change is seen
                num, den = np.sum(np.where(use, de * dp, 0.0), 1), np.sum(np.where(use, dp * dp, 0.0), 1)
                ok = np.sum(use, 1) >= 3
                self.gain_W = np.where(ok, np.clip(num / np.maximum(den, 1e-300), *gain_clip), self.gain_W)
            else:
                self.gain_b = np.where(use, np.clip(de / np.where(use, dp, 1.0), *gain_clip), self.gain_b)
        # a row whose moved entries (nearly) all failed to follow, twice running, is a dead neuron:
        # its whole row (the entries the data do not see too) is pinned at 0, its bias at its value
        dpW, deW = f.W_prog - old.W_prog, f.W - old.W
        movedW = np.abs(dpW) > stuck_z * np.sqrt(f.W_se ** 2 + old.W_se ** 2)
        failed = movedW & (new_flags[0] | self.fixed[0])
        # ... and whose realised row is (near) 0 where the data see it: a row with some stuck weights
        # has its moved entries fail too (the correction moves mostly those), but the rest of it is there
        seen = np.abs(f.W_prog) > 3 * f.W_se
        ratio = np.sqrt(np.sum(np.where(seen, f.W, 0.0) ** 2, 1) / np.maximum(np.sum(np.where(seen, f.W_prog, 0.0) ** 2, 1),
                                                                              1e-300))
        dead_now = (movedW.sum(1) >= 3) & (failed.sum(1) >= 0.8 * movedW.sum(1)) & (seen.sum(1) >= 3) & (ratio < 0.25)
        dead = dead_now & self.dead_flag & ~self.fixed[0].all(1)
        self.dead_flag = dead_now & ~dead
        if np.any(dead):
            self.fixed[0][dead], self.values[0][dead] = True, 0.0
            self.fixed[1][dead], self.values[1][dead] = True, f.b[dead]
            pins += int(dead.sum())
        self.flagged = tuple(new_flags)
        return pins

    def correct(self, f, target, w0, ridge: float, act):
        """The next programmed (W, b) of this layer and the round's report row.

        Per neuron i, the residual map R_i = target_i - realised_i divided by the row's gains is
        projected on what the data see: (G_i + lambda I)^-1 G_i, with G_i the mean over the
        layer's measured inputs of sigma'(z_i)^2 [a, 1] [a, 1]^T at the target (1 at the output
        layer) and lambda ``ridge`` times G_i's mean eigenvalue. A direction the inputs (nearly)
        never take, or along which the neuron is saturated, does not change the layer's output
        on the data: its residual is the fit's noise, and programming it would move the map where
        the data do not show it (a mesh then mixes it into directions they do). The round's
        residual is the output deficit on the data, sqrt(mean_i R_i G_i R_i^T)."""
        step, deficit = correction(f, target, self.fixed, self.gain_W, self.gain_b, ridge, act)
        if self.best is None or deficit <= self.best[0]:
            self.best = (deficit, (f.W_prog, f.b_prog), step)
            self.step = min(1.0, 1.5 * self.step)
            base, d = (f.W_prog, f.b_prog), step
        else:  # worse than the best round: back to it, half the step
            self.step *= 0.5
            _, base, d = self.best
        pW = np.where(self.fixed[0], w0[0], base[0] + self.step * d[:, :-1])
        pb = np.where(self.fixed[1], w0[1], base[1] + self.step * d[:, -1])
        row = {"output_deficit": deficit, "step": self.step,
               "pinned": int(self.fixed[0].sum() + self.fixed[1].sum())}
        return (pW, pb), row


def correction(f, target, fixed, gain_W, gain_b, ridge: float, act):
    """One layer's correction of the programmed (W, b) towards ``target`` from its fit ``f``, as a
    (d, p+1) step, and the output deficit sqrt(mean_i R_i G_i R_i^T) (:meth:`_LayerState.correct`).
    ``fixed``: the pinned (W, b) masks (no step there); ``gain_W``, ``gain_b``: the rows' gains."""
    tW, tb = target
    R = np.concatenate([np.where(~fixed[0], tW - f.W, 0.0), np.where(~fixed[1], tb - f.b, 0.0)[:, None]], axis=1)
    G = _slope_gram(f.inputs_seen, tW, tb, f.hidden, act)
    deficit = float(np.sqrt(np.mean(np.einsum("ip,ipq,iq->i", R, G, R))))
    k = G.shape[1]
    lam = ridge * np.trace(G, axis1=1, axis2=2) / k
    P = np.linalg.solve(G + lam[:, None, None] * np.eye(k), G)          # (d, k, k)
    raw = np.concatenate([R[:, :-1] / gain_W[:, None], R[:, -1:] / gain_b[:, None]], axis=1)
    return np.einsum("ipq,iq->ip", P, raw), deficit


def _slope_gram(A, W, b, hidden: bool, act, chunk: int = 64):
    """Per neuron the mean of sigma'(z)^2 [a, 1][a, 1]^T over the inputs ``A`` (n, r', p) at the map
    (W, b) (d, k, k), k = p + 1; sigma' = 1 without an activation."""
    n, r, p = A.shape
    A1 = np.concatenate([A, np.ones((n, r, 1))], axis=2).reshape(n * r, p + 1)
    if not hidden:
        G = A1.T @ A1 / (n * r)
        return np.broadcast_to(G, (W.shape[0],) + G.shape)
    z = A1 @ np.concatenate([W, b[:, None]], axis=1).T          # (n r, d)
    g2 = act(z) ** 2
    out = np.empty((W.shape[0], p + 1, p + 1))
    for i0 in range(0, W.shape[0], chunk):
        sl = slice(i0, i0 + chunk)
        out[sl] = np.einsum("ni,np,nq->ipq", g2[:, sl], A1, A1, optimize=True) / (n * r)
    return out


def _identified(first, lays, L):
    """What the first round showed per layer, and what the loop pinned (for the report)."""
    out = {}
    for l, f in sorted(first.items()):
        st = lays[l - 1]
        dead = [int(j) for j in np.where(st.fixed[0].all(axis=1))[0]]
        out[str(l)] = {"rows_gain_median": float(np.median(st.gain_W)),
                       "rows_gain_range": [float(np.min(st.gain_W)), float(np.max(st.gain_W))],
                       "bias_gain_median": float(np.median(st.gain_b)),
                       "weight_deviation_rms": float(np.sqrt(np.mean((f.W - f.W_prog) ** 2))),
                       "bias_deviation_rms": float(np.sqrt(np.mean((f.b - f.b_prog) ** 2))),
                       "stuck_weights": int(st.fixed[0].sum()), "stuck_biases": int(st.fixed[1].sum()),
                       "dead_neurons": dead if l < L else [], "noise_level": f.s}
    return out
