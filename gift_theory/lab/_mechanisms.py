"""Stage 7 of the lab: from where the model fails to which mechanism (CONTRACTS §6).

The localised evidence (:func:`~gift_theory.lab._localise.layer_evidence`: per layer, how the
residuals depart from the model, each departure a z) and the candidates' fits are turned into
the ranked ``mechanisms`` list, one class per entry with its layers, its score (a z: how far
the strongest evidence for it stands beyond the model's noise) and one line of evidence.

**This is the one place where a mechanism rule lives.** Each rule is a function
``(ctx) -> (score, layers, evidence) | None`` registered in :data:`RULES` under its class; to
teach the lab a new mechanism, add a rule here. A class is listed when its score exceeds
:data:`THRESHOLD`; the list is sorted by score.

With taps the evidence is each layer's own (its model fed the measured layer before); without
taps only the output is seen, errors of the hidden layers folded into it, and a hidden-layer
class is reported on the hidden layers as a possibility the output cannot localise.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..effects import MECHANISMS, REGISTRY

#: a class is listed when its evidence stands this many standard deviations out
THRESHOLD = 4.0


@dataclasses.dataclass
class Context:
    """What the rules read.

    evidence : {layer: layer_evidence row}
    depth : L
    taps : whether the evidence is per layer (one-step, with taps) or the output only
    failing : the failing layers (with taps), else None
    fit_gain : {class: z} the best moment-fitted candidate of each class: how many baseline
        standard deviations its held-out discrepancy fell below the baseline's
    levels : {layer: (s_layer, level_z)} per-layer noise levels of the one-step check
    """

    evidence: dict
    depth: int
    taps: bool
    failing: list | None
    fit_gain: dict
    levels: dict


def _layers_where(ctx, keys, hidden=None, min_z=THRESHOLD, absolute=True):
    out = []
    for l, row in ctx.evidence.items():
        if hidden is True and l == ctx.depth or hidden is False and l != ctx.depth:
            continue
        vals = [abs(row.get(k, 0.0)) if absolute else row.get(k, 0.0) for k in keys]
        if max(vals) > min_z:
            out.append(l)
    return out


def _best(ctx, keys, hidden=None, absolute=True):
    """The largest evidence among ``keys`` on the layers selected, and its (layer, key)."""
    best, where = 0.0, None
    for l, row in ctx.evidence.items():
        if hidden is True and l == ctx.depth or hidden is False and l != ctx.depth:
            continue
        for k in keys:
            v = row.get(k, 0.0)
            v = abs(v) if absolute else v
            if np.isfinite(v) and v > best:
                best, where = v, (l, k)
    return best, where


def _shared(row, keys=None):
    """The strongest distortion shared by the layer's neurons: each common component, weighed by
    how consistently the neurons' own coefficients agree in sign (a sum over neurons of
    random-sign shifts -- what a weight error or a fluctuating gain leaves -- is not shared)."""
    best, key = 0.0, None
    for k, mix in (("common_offset_z", "offset_mixed"), ("common_slope_z", "slope_mixed"),
                   ("common_curve_z", "curve_mixed")):
        if keys is not None and k not in keys:
            continue
        v = abs(row.get(k, 0.0)) * max(0.0, 1.0 - 2.0 * row.get(mix, 0.0))
        if v > best:
            best, key = v, k
    return best, key


def _best_shared(ctx, hidden):
    best, where = 0.0, None
    for l, row in ctx.evidence.items():
        if hidden is True and l == ctx.depth or hidden is False and l != ctx.depth:
            continue
        v, k = _shared(row)
        if v > best:
            best, where = v, (l, k)
    return best, where


def _line(where, score, extra=""):
    return f"{where[1].replace('_z', '')} z = {score:.1f} at layer {where[0]}{extra}" if where else extra


def _with_fit(ctx, cls, score, layers, text):
    g = ctx.fit_gain.get(cls, 0.0)
    if g > score:
        return g, layers, (text + "; " if text else "") + f"a fitted {cls} effect lowers the held-out discrepancy by {g:.1f} sd"
    return score, layers, text


def rule_activation(ctx):
    """Hidden layers whose mean response is a distorted function of the pre-activation."""
    hidden = list(range(1, ctx.depth))
    if not hidden:
        return None
    if ctx.taps:
        score, where = _best_shared(ctx, hidden=True)
        layers = [l for l, row in ctx.evidence.items() if l < ctx.depth and _shared(row)[0] > THRESHOLD]
        return _with_fit(ctx, "activation_mismatch", score, layers,
                         _line(where, score, " (a distortion of the transfer shared by the neurons)"))
    score, where = _best_shared(ctx, hidden=False)
    return _with_fit(ctx, "activation_mismatch", 0.5 * score, hidden,
                     _line(where, score, " at the output (hidden layers cannot be seen without taps)"))


def rule_readout(ctx):
    """The output's mean response is a distorted function of its own pre-activation -- with taps,
    while the hidden layers respond as modelled. Noise alone does not move the output's mean
    (nothing nonlinear follows it), so where the output's mean is distorted, the output's noise
    evidence (variance, kurtosis) counts for the readout's transfer too."""
    score, where = _best_shared(ctx, hidden=False)
    if score > THRESHOLD and ctx.depth in ctx.evidence:
        row = ctx.evidence[ctx.depth]
        noise = max(abs(row.get("kurt_z", 0.0)), row.get("var_abs_z", 0.0), abs(row.get("var_level_z", 0.0)))
        score = max(score, noise)
    if ctx.taps and ctx.failing and any(l < ctx.depth for l in ctx.failing):
        score *= 0.5  # hidden layers fail too: the output's distortion may be inherited
    return _with_fit(ctx, "readout_nonlinearity", score, [ctx.depth] if score > THRESHOLD else [],
                     _line(where, score, " (the output's transfer)"))


def rule_bias(ctx):
    """Per-neuron constant shifts of the mean, of either sign (offsets drawn per neuron), with no
    shape shared by the neurons (a shift all one way is a distorted transfer)."""
    best, where = 0.0, None
    for l, row in ctx.evidence.items():
        common = max(abs(row.get(k, 0.0)) for k in ("common_slope_z", "common_curve_z", "common_offset_z"))
        z = row.get("bias_z", row.get("offset_z", 0.0))
        mixed = row.get("bias_mixed", row.get("offset_mixed", 1.0))
        # what a shifted bias leaves is a multiple of sigma'(z) per neuron: a reproducible rest is
        # the linear map's (a weight error shifts the means too), a shared shape the transfer's
        v = (z - 0.5 * common - max(row.get("bias_rest_z", 0.0), 0.0)) * min(1.0, 2.0 * mixed)
        if v > best:
            best, where = v, (l, "bias_z" if "bias_z" in row else "offset_z")
    layers = [l for l, row in ctx.evidence.items() if row.get("bias_z", row.get("offset_z", 0.0)) > THRESHOLD]
    return _with_fit(ctx, "bias_offset", best, layers,
                     _line(where, best, " (per-neuron shifts along sigma'(z), either sign, nothing left over)"))


def rule_weight(ctx):
    """Reproducible mean residuals that no per-neuron function of z explains: the linear map."""
    score, where = _best(ctx, ("structure_z",), absolute=False)
    return _with_fit(ctx, "weight_error", score, _layers_where(ctx, ("structure_z",), absolute=False),
                     _line(where, score, " (reproducible beyond every per-neuron response curve)"))


def rule_input_dependent(ctx):
    score, where = _best(ctx, ("var_abs_z",), absolute=False)
    return _with_fit(ctx, "input_dependent_noise", score, _layers_where(ctx, ("var_abs_z",), absolute=False),
                     _line(where, score, " (excess variance growing with |z|)"))


def rule_law(ctx):
    score, where = _best(ctx, ("kurt_z",))
    return _with_fit(ctx, "noise_law", score, _layers_where(ctx, ("kurt_z",)), _line(where, score, " (kurtosis)"))


def rule_gain(ctx):
    score, where = _best(ctx, ("corr_z", "time_z"), absolute=True)
    return _with_fit(ctx, "gain_fluctuation", score, _layers_where(ctx, ("corr_z", "time_z")),
                     _line(where, score, " (fluctuation shared by the neurons, or a trend in time)"))


def rule_level(ctx):
    """A layer whose own noise level differs from the jointly fitted one, and which passes its
    one-step check at its own level (its level is all that is wrong there)."""
    best, layer = 0.0, None
    if ctx.failing:  # a failing layer's misfit sets the joint level: the levels say nothing then
        return 0.0, [], ""
    for l, (s_l, z) in ctx.levels.items():
        if abs(z) > best:
            best, layer = abs(z), l
    layers = [l for l, (_, z) in ctx.levels.items() if abs(z) > THRESHOLD]
    text = (f"layer {layer}'s own noise level {ctx.levels[layer][0]:.3g} (variance z = {ctx.levels[layer][1]:.1f} "
            f"at the joint level)" if layer is not None else "")
    return _with_fit(ctx, "noise_level", best, layers, text)


#: class -> rule (CONTRACTS §6's classes)
RULES = {
    "noise_level": rule_level,
    "noise_law": rule_law,
    "input_dependent_noise": rule_input_dependent,
    "gain_fluctuation": rule_gain,
    "weight_error": rule_weight,
    "bias_offset": rule_bias,
    "activation_mismatch": rule_activation,
    "readout_nonlinearity": rule_readout,
}
assert set(RULES) == set(MECHANISMS), "every CONTRACTS §6 class has a rule"


def fit_gains(ranking, base_cmp, prior=None, alpha: float = 0.01, share: float = 0.5) -> dict:
    """{class: z}: for each class with a moment-fitted candidate that passes its held-out test or
    removes at least ``share`` of the baseline's excess over the noise floor, how far (in the
    baseline's sd of Q) its discrepancy fell below the baseline's. A candidate that removes
    less is no evidence for its class (an extra parameter absorbs part of any misfit); an
    offset family counts only when it passes, the data identify its values and they look like
    its own effect (``prior``: model -> :func:`~gift_theory.lab._fit_offsets.prior_check` rows on
    the fitting half; None skips that check): with
    hundreds of free values it lowers the discrepancy whatever the physics. Weight offsets that
    pass but are refused only as coupled to the programmed weights (``w_structure``,
    ``w_coupling``) are a structured weight error: they count for ``weight_error``."""
    from ._fit_offsets import fitted_as_offsets, refusing

    out = {}
    unit = base_cmp.se if base_cmp.se > 0 else 1.0
    excess = base_cmp.discrepancy - base_cmp.noise_floor
    for c in ranking:
        if len(c.effects) != 1:
            continue
        removed = (base_cmp.discrepancy - c.comparison.discrepancy) / excess if excess > 0 else 0.0
        if fitted_as_offsets(c.effects[0]):
            # an offset family counts only when it passes with values the data identify
            if c.comparison.p_value < alpha or c.n_free < 0.5 * c.nominal:
                continue
            refused = refusing(prior(c.model)) if prior is not None else []
            coupled = {"w_structure", "w_coupling"}
            if refused and not (REGISTRY[c.effects[0]].mechanism == "weight_error"
                                and all(r["test"] in coupled for r in refused)):
                continue
        elif c.comparison.p_value < alpha and removed < share:
            continue
        cls = REGISTRY[c.effects[0]].mechanism
        g = (base_cmp.discrepancy - c.comparison.discrepancy) / unit
        out[cls] = max(out.get(cls, 0.0), float(g))
    return out


def mechanisms(ctx: Context) -> list[dict]:
    """The ranked mechanism classes the evidence points to (score > :data:`THRESHOLD`)."""
    out = []
    for cls, rule in RULES.items():
        r = rule(ctx)
        if r is None:
            continue
        score, layers, text = r
        if np.isfinite(score) and score > THRESHOLD:
            out.append({"mechanism": cls, "layers": sorted(int(l) for l in layers), "score": float(score),
                        "evidence": text})
    out.sort(key=lambda m: -m["score"])
    return out
