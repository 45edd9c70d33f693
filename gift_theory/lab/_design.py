"""The measurement that would tell the hypotheses left standing apart (reference §8).

**The hypotheses.** When the data cannot choose between models that explain them
(:mod:`._ambiguity`), those models; when nothing explains the data, the best-ranked fitted
candidate of each of the first two mechanism classes the diagnosis lists (else the two
best-ranked candidates of different classes). Each is a fitted model: its physics at the values
fitted on the file (and its fitted offsets).

**The designs** (:func:`designs`), each a campaign on the same chip with the same programmed
weights: the same inputs again (the first design, as a yardstick); the inputs at half and twice
their amplitude, and spread twice as wide about their mean (another range); a tap on one hidden
layer (a file without taps); the shots in random order (a file acquired input by input);
a second campaign later in time (its times after the first's: a drift keeps going, a fixed
error does not). Each also with more shots per input (k times the file's r).

**The separating statistic** of two hypotheses a and b on a campaign: the Gaussian
quasi-log-likelihood ratio of the cells (input x neuron of every measured layer; with times, each
input's shots split into its earlier and later half), each cell's mean and variance as each
hypothesis predicts them (:data:`MODEL_SHOTS` model shots per cell)::

    T = sum_cells [ l_a(cell) - l_b(cell) ],   l_H = -r' ((ybar - mu_H)^2 + s^2) / (2 sigma_H^2) - r' log sigma_H

**Predicted power.** T is simulated under each hypothesis (:data:`REPLICATES` campaigns of the
design from each fitted model, its own draws). b is rejected in favour of a when T exceeds the
99th percentile of T under b, a in favour of b when T is below the 1st percentile under a (the
percentiles from the normal law with T's simulated mean and standard deviation); the design's
power is the smaller of P_a(reject b) and P_b(reject a), over every pair of hypotheses. With k
times the shots, T's mean difference grows as k and its spread as sqrt(k): each design's power
is extrapolated to the k that reaches :data:`POWER`, the cheapest design (fewest shots, then no
tap, then the order of :func:`designs`) is simulated again at that k, and returned with its
simulated power. When no design reaches :data:`POWER` within :data:`MAX_FACTOR` times the file's
shots, the most powerful one at that size is returned with its (lower) power.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from .._measurement import Measurement
from .._model import named_subkey
from ._ambiguity import classes_of
from ._level import ALPHA
from ._shots import model_shots

#: the power a design must reach at the 0.01 level
POWER = 0.8
#: simulated campaigns per hypothesis and design (an even number)
REPLICATES = 16
#: model shots per input behind each hypothesis' predicted cell means and variances (at least)
MODEL_SHOTS = 256
#: the largest multiple of the file's shots considered
MAX_FACTOR = 64
#: at most this many inputs in a simulated campaign (a larger file's design is simulated on a
#: random subset and its statistic scaled: cells are independent across inputs)
MAX_INPUTS = 240


@dataclasses.dataclass(frozen=True)
class Design:
    """One campaign to run: ``x`` (n, d_0) the inputs, ``r`` shots each, ``taps`` the hidden layers
    measured, ``order`` "random" | "blocked" (input by input), ``later``: its times after the
    file's (a second campaign later in time)."""

    kind: str
    text: str
    x: np.ndarray
    r: int
    taps: tuple
    order: str
    later: bool = False

    def shots(self) -> int:
        return int(self.x.shape[0] * self.r)

    def at(self, k: int) -> "Design":
        return dataclasses.replace(self, r=int(self.r * k))


def _blocked(meas: Measurement) -> bool:
    return meas.t is not None and float(np.std(np.asarray(meas.t).mean(1))) >= 0.1


def designs(meas: Measurement) -> list:
    """The candidate campaigns (see the module), in the order that breaks ties of cost."""
    n, r, L = meas.n, meas.r, meas.arch.depth
    x = np.asarray(meas.x, np.float64)
    own = tuple(range(1, L)) if meas.has_taps else ()
    order = "blocked" if _blocked(meas) else "random"
    how = "input by input" if order == "blocked" else "in random order"
    out = [Design("repeat", f"the same {n} inputs again ({how})", x, r, own, order),
           Design("amplitude_2", f"the {n} inputs at twice their amplitude", 2.0 * x, r, own, order),
           Design("amplitude_0.5", f"the {n} inputs at half their amplitude", 0.5 * x, r, own, order),
           Design("range_2", f"the {n} inputs spread twice as wide about their mean",
                  x.mean(0) + 2.0 * (x - x.mean(0)), r, own, order)]
    if not meas.has_taps:
        out += [Design(f"tap_{l}", f"the same {n} inputs with a tap on layer {l}", x, r, (l,), order)
                for l in range(1, L)]
    if order == "blocked":
        out.append(Design("random_order", f"the same {n} inputs, their shots in random order", x, r, own, "random"))
    if meas.t is not None:
        out.append(Design("later", f"the same {n} inputs in a second campaign after this one ({how})", x, r, own,
                          order, later=True))
    return out


def hypotheses(ranking, mechs, others) -> list:
    """The fitted candidates to tell apart (see the module); [] when fewer than two."""
    if others:
        return [ranking[0]] + list(others)
    picks = []
    for m in mechs or ():
        c = next((c for c in ranking if m["mechanism"] in classes_of(c) and c not in picks), None)
        if c is not None:
            picks.append(c)
        if len(picks) == 2:
            return picks
    for c in ranking:
        if len(picks) == 2:
            break
        if c not in picks and all(classes_of(c) != classes_of(p) for p in picks):
            picks.append(c)
    return picks if len(picks) == 2 else []


def _times(n: int, r: int, order: str, rng, later: bool) -> np.ndarray:
    if order == "blocked":
        rank = np.arange(n * r).reshape(n, r)
    else:
        rank = np.argsort(rng.permutation(n * r)).reshape(n, r)
    return rank / max(n * r - 1, 1) + (1.0 if later else 0.0)


def campaign(meas: Measurement, design: Design, seed: int = 0) -> Measurement:
    """The design as a measurement to simulate (y and taps zero: shapes only; every hidden layer
    tapped, the statistic reads the design's)."""
    n, r = design.x.shape[0], design.r
    L = meas.arch.depth
    rng = np.random.default_rng([48, seed, n, r])
    t = _times(n, r, design.order, rng, design.later) if meas.t is not None or design.order == "random" else None
    widths = meas.arch.widths
    taps = tuple(np.zeros((n, r, widths[l])) for l in range(1, L)) if L > 1 else None
    return Measurement(np.asarray(design.x, np.float64), np.zeros((n, r, widths[L])), meas.params, taps, t,
                       meas.activation)


def _cells(layers, t, halves: bool):
    """Per cell (input x neuron, and with ``halves`` each input's earlier and later shots): the mean
    and the biased variance of the shots, over the layers given ((n, r, d) each)."""
    Y = np.concatenate([np.asarray(a, np.float64) for a in layers], axis=2)
    if not halves or t is None:
        return Y.mean(1)[None], Y.var(1)[None], Y.shape[1]
    order = np.argsort(np.asarray(t), axis=1, kind="stable")
    Ys = np.take_along_axis(Y, order[:, :, None], axis=1)
    h = Y.shape[1] // 2
    parts = [Ys[:, :h], Ys[:, h:2 * h]]
    return np.stack([p.mean(1) for p in parts]), np.stack([p.var(1) for p in parts]), h


def _statistic(data, pred_a, pred_b, r: int):
    """T of the module over the cells: data (means, variances), pred_H (means, variances)."""
    m, v = data[0], data[1]
    out = 0.0
    for (mu, s2), sign in ((pred_a[:2], 1.0), (pred_b[:2], -1.0)):
        s2 = np.maximum(s2, 1e-12)
        out = out + sign * float(np.sum(-r * ((m - mu) ** 2 + v) / (2.0 * s2) - 0.5 * r * np.log(s2)))
    return out


def _simulate(key, model, camp: Measurement, layer_idx, halves: bool, copies: int):
    """``copies`` campaigns of ``model`` on ``camp`` (one call: the model's shots in blocks of the
    campaign's r, each block a campaign with the campaign's times), each one's cells on the layers
    read."""
    r = camp.r
    outs = model_shots(key, model, camp, copies * r)
    return [_cells([outs[i][:, c * r:(c + 1) * r] for i in layer_idx], camp.t, halves) for c in range(copies)]


def _pooled(cells) -> tuple:
    """A hypothesis' predicted cell means and variances: the mean over many campaigns' cells."""
    return np.mean([c[0] for c in cells], axis=0), np.mean([c[1] for c in cells], axis=0)


def _predict(key, hyps, meas: Measurement, design: Design, replicates: int):
    """Each hypothesis' predicted cells on the design and ``replicates`` simulated campaigns' cells:
    ``(preds, sims, layer_idx, halves, r_eff, scale, sub)``."""
    n = design.x.shape[0]
    sub = design
    scale = 1.0
    if n > MAX_INPUTS:  # simulate on a subset of the inputs; T adds up over inputs
        idx = np.sort(np.random.default_rng([48, n]).choice(n, MAX_INPUTS, replace=False))
        sub = dataclasses.replace(design, x=design.x[idx])
        scale = n / MAX_INPUTS
    camp = campaign(meas, sub)
    ids = camp.layer_ids()
    layer_idx = [ids.index(l) for l in sorted(set(design.taps) | {meas.arch.depth})]
    halves = camp.t is not None and sub.r >= 4
    copies = 2 * max(1, -(-MODEL_SHOTS // (2 * sub.r)))  # the predictions' campaigns (an even number)
    preds, sims = [], []
    for j, h in enumerate(hyps):
        kj = named_subkey(key, f"hyp{j}")
        preds.append(_pooled(_simulate(named_subkey(kj, "pred"), h.model, camp, layer_idx, halves, copies)))
        sims.append(_simulate(named_subkey(kj, "data"), h.model, camp, layer_idx, halves, replicates))
    return preds, sims, layer_idx, halves, (sub.r // 2 if halves else sub.r), scale, sub


def _pair_laws(preds, sims, r_eff, scale):
    """Per pair (a, b): T's mean and spread under a and under b."""
    out = {}
    for a in range(len(preds)):
        for b in range(a + 1, len(preds)):
            Ta = np.array([_statistic(d, preds[a], preds[b], r_eff) for d in sims[a]]) * scale
            Tb = np.array([_statistic(d, preds[a], preds[b], r_eff) for d in sims[b]]) * scale
            out[(a, b)] = (Ta.mean(), max(Ta.std(ddof=1), 1e-12), Tb.mean(), max(Tb.std(ddof=1), 1e-12))
    return out


def _power(key, hyps, meas: Measurement, design: Design, replicates: int):
    """The design's simulated power (min over ordered pairs of hypotheses) and, per pair, the
    statistic's mean gap and spreads under each (for the extrapolation in shots)."""
    preds, sims, _, _, r_eff, scale, _ = _predict(key, hyps, meas, design, replicates)
    z99 = stats.norm.isf(ALPHA)
    worst, pairs = 1.0, []
    for (ma, sa, mb, sb) in _pair_laws(preds, sims, r_eff, scale).values():
        pa = float(stats.norm.sf((mb + z99 * sb - ma) / sa))  # data from a reject b
        pb = float(stats.norm.cdf((ma - z99 * sa - mb) / sb))  # data from b reject a
        worst = min(worst, pa, pb)
        pairs.append((ma - mb, sa, sb))
    return worst, pairs


def decide(key, hyps, meas: Measurement, design: Design, data: Measurement, replicates: int = REPLICATES) -> dict:
    """The separating test on a measured campaign of ``design`` (``data``: its shots, same inputs,
    shots and times): ``{name: rejected}`` -- a hypothesis is rejected when for some other one the
    statistic falls beyond its 1 % tail (T above b's 99th percentile rejects b; below a's 1st, a),
    the laws simulated as for the power (the same key gives the same laws)."""
    preds, sims, _, halves, r_eff, scale, sub = _predict(key, hyps, meas, design, replicates)
    laws = _pair_laws(preds, sims, r_eff, scale)
    if sub is not design:
        raise ValueError("decide: a campaign of at most MAX_INPUTS inputs")
    ids = list(data.layer_ids())
    read = sorted(set(design.taps) | {meas.arch.depth})
    cells = _cells([data.layers()[ids.index(l)] for l in read], data.t, halves)
    z99 = stats.norm.isf(ALPHA)
    rejected = [False] * len(hyps)
    for (a, b), (ma, sa, mb, sb) in laws.items():
        T = _statistic(cells, preds[a], preds[b], r_eff) * scale
        rejected[b] |= T > mb + z99 * sb
        rejected[a] |= T < ma - z99 * sa
    return {"+".join(h.effects): bool(x) for h, x in zip(hyps, rejected)}


def _factor(pairs) -> float:
    """The multiple k of the shots at which every pair reaches :data:`POWER` (T's mean gap grows as
    k, its spread as sqrt(k)); inf when the gap has the wrong sign."""
    z99, z80 = stats.norm.isf(ALPHA), stats.norm.isf(1.0 - POWER)
    k = 0.0
    for gap, sa, sb in pairs:
        if gap <= 0:
            return math.inf
        # both directions: gap k >= z99 s_b sqrt(k) + z80 s_a sqrt(k) and the same with a, b swapped
        need = max(z99 * sb + z80 * sa, z99 * sa + z80 * sb) / gap
        k = max(k, need * need)
    return k


def _base_powers(key, hyps, meas: Measurement, base, replicates: int) -> list:
    """:func:`_power` of each design of ``base`` (None where a hypothesis cannot be simulated on
    it), the designs in the lab's threads (:func:`~._budget.map_in_threads`): each is keyed by its
    kind alone."""
    from ._budget import default_workers, map_in_threads

    def one(dz):
        try:
            return _power(named_subkey(key, dz.kind), hyps, meas, dz, replicates)
        except Exception:
            return None

    return map_in_threads(one, base, default_workers(meas))


def next_measurement(key, meas: Measurement, ranking, mechs, others, base_cmp=None, replicates: int = REPLICATES):
    """The cheapest design that separates the hypotheses left standing with power >= :data:`POWER`
    at :data:`ALPHA` (see the module), as reference §8's object, or None when fewer than two
    hypotheses are left (or none can be simulated)."""
    hyps = hypotheses(ranking, mechs, others)
    if len(hyps) < 2:
        return None
    base = designs(meas)
    scored = []
    for i, (dz, powered) in enumerate(zip(base, _base_powers(key, hyps, meas, base, replicates))):
        if powered is None:  # a hypothesis that cannot be simulated on this design (e.g. times it needs)
            continue
        pw, pairs = powered
        k = _factor(pairs)
        if pw >= POWER:
            k = 1.0
        kk = 1 if k <= 1 else 2 ** math.ceil(math.log2(k)) if math.isfinite(k) else math.inf
        scored.append((kk * dz.shots() if math.isfinite(kk) else math.inf, len(dz.taps) - len(base[0].taps), i,
                       dz, kk, pw))
    if not scored:
        return None
    scored.sort(key=lambda s: s[:3])
    names = ["+".join(h.effects) for h in hyps]
    for cost, _, _, dz, kk, pw0 in scored:
        if not math.isfinite(cost) or kk > MAX_FACTOR:
            break
        pick = dz.at(kk)
        pw = pw0 if kk == 1 else _power(named_subkey(key, dz.kind + f"x{kk}"), hyps, meas, pick, replicates)[0]
        if pw >= POWER or kk == MAX_FACTOR:
            return _as_json(pick, names, pw, meas)
    # nothing reaches the power within MAX_FACTOR: the most powerful design at the largest size
    best = max(scored, key=lambda s: s[5])
    pick = best[3].at(MAX_FACTOR)
    pw = _power(named_subkey(key, best[3].kind + "max"), hyps, meas, pick, replicates)[0]
    return _as_json(pick, names, pw, meas)


def _as_json(dz: Design, names, power: float, meas: Measurement) -> dict:
    text = f"{dz.text}, {dz.r} shots each ({dz.shots()} shots)"
    if dz.taps and not meas.has_taps:
        text += f", tapping layer(s) {', '.join(map(str, dz.taps))}"
    return {"design": text, "kind": dz.kind, "separates": list(names), "power": float(power), "shots": dz.shots(),
            "inputs": int(dz.x.shape[0]), "taps": [int(l) for l in dz.taps], "order": dz.order,
            "later": bool(dz.later), "r": int(dz.r), "_x": dz.x}


def inputs_arrays(nxt: dict) -> dict:
    """The arrays ``gift design --out`` writes: the inputs to send and how to measure them."""
    return {"x": np.asarray(nxt["_x"], np.float64), "shots": np.array(int(nxt["r"])),
            "taps": np.array(nxt["taps"], dtype=np.int64), "order": np.array(nxt["order"]),
            "later": np.array(bool(nxt["later"]))}


def public(nxt: dict | None) -> dict | None:
    """The JSON object (without the inputs array)."""
    return None if nxt is None else {k: v for k, v in nxt.items() if not k.startswith("_")}
