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
identified, and the report says so.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._params import Layer, params32
from .._phases import phase
from ..effects import awgn
from ._fit import fit_layers


def _np(params):
    return [(np.array(W, np.float64), np.array(b, np.float64)) for W, b in params]


def _layers32(params):
    return params32(tuple(Layer(W, b) for W, b in params))


def _pinned(fixed, values, like):
    from ..training import Pinned
    mask = tuple(Layer(jnp.asarray(mW), jnp.asarray(mb)) for mW, mb in fixed)
    val = tuple(Layer(jnp.asarray(vW, jnp.float32), jnp.asarray(vb, jnp.float32)) for vW, vb in values)
    return Pinned(mask, val)


def _retrain_target(problem, start, fixed, values, s_hat: float, seed: int):
    """The target retrained in silico under awgn(s_hat) with the pinned entries held at their values."""
    from ..finetune._rivals import RETRAIN
    from ..training import train

    key = jax.random.fold_in(problem.key, 7100 + seed)
    out = train(key, problem.arch, problem.x, problem.y, awgn(s_hat), RETRAIN, params=_layers32(start),
                pinned=_pinned(fixed, values, start))
    return _np(out)


def _row_gain(W_eff, W):
    num = np.sum(W_eff * W, axis=1)
    den = np.sum(W * W, axis=1)
    return np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)


def calibrate(problem, *, inputs: int = 256, shots: int = 8, rounds: int = 6, reserve: float = 4.0,
              z_accept: float = 2.5, stuck_z: float = 5.0, stuck_ratio: float = 0.25, gain_clip=(0.4, 2.5),
              noise_tolerance: float = 0.1, retrain: bool = True):
    """Calibrate the chip of ``problem`` to realise w0 (module docstring).

    Parameters
    ----------
    problem : :class:`~gift_theory.finetune.Problem` (its chip: any Chip; taps used where it has them)
    inputs, shots : each round measures ``inputs`` fine-tuning inputs ``shots`` times
    rounds : at most this many measure-and-correct rounds
    reserve : chip evaluations kept for the confirmation (two per paired round)
    z_accept : the confirmation's overall one-sided level P(Z > z_accept)
    stuck_z, stuck_ratio : an entry is stuck when its programmed value moved by more than
        ``stuck_z`` standard errors of the realised change and its realised value followed by less
        than ``stuck_ratio`` of the row's gain
    gain_clip : the range a row's gain estimate is held in (a step never more than 1/0.4 of the residual)
    noise_tolerance : retrain under the identified noise level when it differs from s0 by more than this share
    retrain : False never retrains (pre-compensation only)

    Returns
    -------
    params, info (``identified``: what each layer showed; ``rounds``: each round's residual;
    ``accepted``/``reason``: the confirmation; ``not_identified``: what the chip's data could not show)
    """
    w0 = _np(problem.w0)
    L = len(w0)
    n = int(min(inputs, problem.K1))
    order = np.asarray(jax.random.permutation(jax.random.fold_in(problem.key, 7000), problem.K1))
    x_cal = problem.x_ft[np.sort(order[:n])]
    cost = n * int(shots) / problem.unit_shots
    target = [(W.copy(), b.copy()) for W, b in w0]
    prog = [(W.copy(), b.copy()) for W, b in w0]
    fixed = [(np.zeros(W.shape, bool), np.zeros(b.shape, bool)) for W, b in w0]
    values = [(np.zeros(W.shape), np.zeros(b.shape)) for W, b in w0]
    gain_W = [np.ones(W.shape[0]) for W, _ in w0]
    gain_b = [np.ones(W.shape[0]) for W, _ in w0]
    prev, s_hat, taps, retrained, history, first = None, None, None, 0, [], {}
    for k in range(int(rounds)):
        if problem.evaluations_left() < cost + reserve - 1e-9:
            break
        with phase("chip"):
            meas = problem.chip.measure(_layers32(prog), x_cal, int(shots), taps=True)
        with phase("calibration fit"):
            fits = fit_layers(meas, s=s_hat)
        taps = meas.has_taps
        s_hat = float(np.exp(np.mean([np.log(f.s) for f in fits])))
        new_pins = 0
        for f in fits:
            i = f.layer - 1
            if prev is None:
                gain_W[i] = np.clip(_row_gain(f.W, f.W_prog), *gain_clip)
                first[f.layer] = f
                continue
            old = prev[f.layer]
            dpW, dpb = f.W_prog - old.W_prog, f.b_prog - old.b_prog
            deW, deb = f.W - old.W, f.b - old.b
            seW = np.sqrt(f.W_se ** 2 + old.W_se ** 2)
            seb = np.sqrt(f.b_se ** 2 + old.b_se ** 2)
            movedW, movedb = np.abs(dpW) > stuck_z * seW, np.abs(dpb) > stuck_z * seb
            stW = movedW & (np.abs(deW) < stuck_ratio * gain_W[i][:, None] * np.abs(dpW)) & ~fixed[i][0]
            stb = movedb & (np.abs(deb) < stuck_ratio * gain_b[i] * np.abs(dpb)) & ~fixed[i][1]
            fixed[i][0][stW], fixed[i][1][stb] = True, True
            values[i][0][stW], values[i][1][stb] = f.W[stW], f.b[stb]
            new_pins += int(stW.sum() + stb.sum())
            # the rows' gains: realised over programmed change, where the programmed change is seen
            use = movedW & ~fixed[i][0]
            num, den = np.sum(np.where(use, deW * dpW, 0.0), 1), np.sum(np.where(use, dpW * dpW, 0.0), 1)
            ok = np.sum(use, 1) >= 3
            gain_W[i] = np.where(ok, np.clip(num / np.maximum(den, 1e-300), *gain_clip), gain_W[i])
            okb = movedb & ~fixed[i][1]
            gain_b[i] = np.where(okb, np.clip(deb / np.where(okb, dpb, 1.0), *gain_clip), gain_b[i])
        mismatch = abs(s_hat / problem.s0 - 1.0) > noise_tolerance
        if retrain and (new_pins or (prev is None and mismatch)):
            with phase("calibration retrain"):
                start = [(np.where(fW, vW, W), np.where(fb, vb, b))
                         for (W, b), (fW, fb), (vW, vb) in zip(target, fixed, values)]
                target = _retrain_target(problem, start, fixed, values, s_hat if mismatch else problem.s0, k)
            retrained += 1
        row = {"round": k, "inputs": n, "shots": int(shots), "noise_level": s_hat, "pinned_new": new_pins,
               "layers": {}}
        for f in fits:
            i = f.layer - 1
            tW, tb = target[i]
            free = ~fixed[i][0]
            zW = (tW - f.W) / f.W_se
            row["layers"][str(f.layer)] = {
                "rms_residual": float(np.sqrt(np.mean(np.where(free, tW - f.W, 0.0) ** 2))),
                "chi2_per_entry": float(np.mean(np.where(free, zW, 0.0) ** 2)),
                "pinned": int(fixed[i][0].sum() + fixed[i][1].sum())}
            pW = f.W_prog + np.where(free, (tW - f.W) / gain_W[i][:, None], 0.0)
            pW = np.where(fixed[i][0], w0[i][0], pW)
            pb = f.b_prog + np.where(~fixed[i][1], (tb - f.b) / gain_b[i], 0.0)
            pb = np.where(fixed[i][1], w0[i][1], pb)
            prog[i] = (pW, pb)
        if not taps:  # the hidden layers are not read: programmed as the target
            prog[:L - 1] = [(W.copy(), b.copy()) for W, b in target[:L - 1]]
        history.append(row)
        prev = {f.layer: f for f in fits}
    info = {"rounds": history, "taps": taps, "retrained": retrained, "noise_level": s_hat,
            "identified": _identified(first, fixed, gain_W, gain_b, taps, L),
            "not_identified": [] if taps else
            ["the hidden layers' maps, stuck weights and dead neurons (no taps: only the output map is read)"]}
    if not history:
        info.update(accepted=False, reason="budget below one round and the confirmation: nothing measured")
        return problem.w0, info
    from ..finetune._linesearch import confirm
    final = _layers32(prog)
    with phase("chip"):
        accepted, conf = confirm(problem, final, z_accept=z_accept)
    info.update(conf, accepted=accepted)
    return (final if accepted else problem.w0), info


def _identified(first, fixed, gain_W, gain_b, taps, L):
    """What the first round showed per layer, and what the loop pinned (for the report)."""
    out = {}
    for l, f in sorted(first.items()):
        i = l - 1
        dead = [int(j) for j in np.where(fixed[i][0].all(axis=1))[0]]
        out[str(l)] = {"rows_gain_median": float(np.median(gain_W[i])),
                       "rows_gain_range": [float(np.min(gain_W[i])), float(np.max(gain_W[i]))],
                       "bias_gain_median": float(np.median(gain_b[i])),
                       "weight_deviation_rms": float(np.sqrt(np.mean((f.W - f.W_prog) ** 2))),
                       "bias_deviation_rms": float(np.sqrt(np.mean((f.b - f.b_prog) ** 2))),
                       "stuck_weights": int(fixed[i][0].sum()), "stuck_biases": int(fixed[i][1].sum()),
                       "dead_neurons": dead if l < L else [], "noise_level": f.s}
    return out
