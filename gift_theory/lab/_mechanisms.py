"""Stage 7 of the lab: from what is measured to which mechanism (reference §6).

The backbone is the layer-wise identification (:func:`~gift_theory.lab.identification.identify`):
per layer, the effective mean map, the activation's shape and the noise read off the shots,
each reference §6 class a test on these estimates with its own p-value (Holm-adjusted over
classes x layers), an effect size and its layers. A class is listed when a test of it names it
(:func:`named`: adjusted p-value below :data:`ALPHA`, and without taps a z beyond
:data:`THRESHOLD`), with the layers where it is, its score (the strongest test's z,
unbounded) and one line of evidence; the list is sorted by score. The catalogue effects fitted by the
diagnosis then confirm and quantify: a fitted effect of a listed class adds its gain in
held-out discrepancy to the evidence line (it never lists a class by itself).

**This is the one place where a mechanism rule lives.** Each rule is a function
``(ctx) -> (score, layers, evidence, p_value) | None`` registered in :data:`RULES` under its
class; to teach the lab a new mechanism, add a rule here (and a test in ``identification``).
Without an identification (a caller that passes none) the rules fall back on the localised
evidence of :func:`~gift_theory.lab._localise.layer_evidence` (each departure a z; listed
beyond :data:`THRESHOLD`, p-value the normal tail of the score).

With taps the identification is each layer's own (its input the measured layer before);
without taps only the output is identified, every layer's deviation folded into it: a class
found there is reported at the output, and an output transfer is also listed as a possible
hidden activation (the two cannot be told apart there; docs/identification.md). There the
candidate mechanisms put into the model (:mod:`._explain_output`) then re-attribute the map
classes: a class one of whose candidates reproduces the output's mean leads them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from ..effects import MECHANISMS, REGISTRY
from ._explain_output import order_map_classes
from ._level import ALPHA
from .identification._trend import TREND_SHARE

#: without an identification, a class is listed when its evidence stands this many standard deviations out
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
    ident : the layer-wise :class:`~gift_theory.lab.identification.Identification`, or None (the
        rules then read ``evidence`` only)
    """

    evidence: dict
    depth: int
    taps: bool
    failing: list | None
    fit_gain: dict
    levels: dict
    ident: object = None

    def __post_init__(self):
        self.rows = self.ident.rows() if self.ident is not None else []


def named(row: dict, taps: bool) -> bool:
    """Whether an identification test names its class: it rejects after Holm's correction, with
    taps or without (``taps`` is kept for callers that read it). Without taps the noise tests
    read the output's shots against the hidden layers' noise propagated by Monte Carlo; they
    once needed z > 4 besides (6 of 100 random null networks named a class: a noise variance
    modelled at a W_eff overfitted along directions the inputs barely span, and the mean of a
    skewed kurtosis over 80 inputs). Both mended, none of those 100 null networks names a class
    at 0.01 (``studies/results/2026-11-28``); with taps 0-1 of 100, 5 at 0.05."""
    return row["p_adj"] < ALPHA


def named_classes(ident) -> dict:
    """``{class: smallest Holm-adjusted p}`` of the identification's tests that name their class
    (:func:`named`): what the verdict's rules 1, b'' and b''' read."""
    out: dict = {}
    for row in ([] if ident is None else ident.rows()):
        if named(row, ident.taps):
            out[row["class"]] = min(out.get(row["class"], 1.0), float(row["p_adj"]))
    return out


def _significant(ctx, cls, layers=None):
    return [r for r in ctx.rows if r["class"] == cls and named(r, ctx.taps)
            and (layers is None or r["layer"] in layers)]


def _identified(ctx, cls, exclude=(), tests=None):
    """(score, layers, evidence, p_value) of ``cls`` from the identification's tests: the layers
    where a test of the class rejects after Holm's correction (less ``exclude``; only the tests
    ``tests`` accepts, when given), the strongest such test's z and evidence, the smallest
    adjusted p-value; None when none rejects."""
    rows = [r for r in _significant(ctx, cls) if r["layer"] not in exclude and (tests is None or tests(r["test"]))]
    if not rows:
        return None
    best = max(rows, key=lambda r: r["z"])
    layers = sorted({int(l) for r in rows for l in r.get("layers", [r["layer"]])})
    text = best["evidence"]
    if not ctx.taps:
        text += " (seen at the output: without taps every layer's deviation folds into it)"
    g = ctx.fit_gain.get(cls, 0.0)
    if g > 0:
        text += f"; a fitted {cls} effect lowers the held-out discrepancy by {g:.1f} sd"
    return float(best["z"]), layers, text, float(min(r["p_adj"] for r in rows))


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
    """Hidden layers whose mean response is a distorted function of the pre-activation (a dead
    or stuck neuron included); without taps, an output transfer may be a hidden activation."""
    if ctx.ident is not None:
        if ctx.taps:
            return _identified(ctx, "activation_mismatch")
        # a lattice is a digitising readout's, never an activation's (continuous by nature)
        r = _identified(ctx, "readout_nonlinearity", tests=lambda test: test != "lattice")
        if r is None or ctx.depth < 2:
            return None
        return (r[0] * 0.99, list(range(1, ctx.depth)), "the output's transfer is distorted; without taps a hidden "
                "activation cannot be told from the readout: " + r[2], r[3])
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
    if ctx.ident is not None:
        return _identified(ctx, "readout_nonlinearity")
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
    if ctx.ident is not None:
        return _identified(ctx, "bias_offset")
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
    if ctx.ident is not None:
        return _identified(ctx, "weight_error")
    score, where = _best(ctx, ("structure_z",), absolute=False)
    return _with_fit(ctx, "weight_error", score, _layers_where(ctx, ("structure_z",), absolute=False),
                     _line(where, score, " (reproducible beyond every per-neuron response curve)"))


def rule_input_dependent(ctx):
    if ctx.ident is not None:
        return _identified(ctx, "input_dependent_noise")
    score, where = _best(ctx, ("var_abs_z",), absolute=False)
    return _with_fit(ctx, "input_dependent_noise", score, _layers_where(ctx, ("var_abs_z",), absolute=False),
                     _line(where, score, " (excess variance growing with |z|)"))


def rule_law(ctx):
    if ctx.ident is not None:
        return _identified(ctx, "noise_law")
    score, where = _best(ctx, ("kurt_z",))
    return _with_fit(ctx, "noise_law", score, _layers_where(ctx, ("kurt_z",)), _line(where, score, " (kurtosis)"))


def rule_gain(ctx):
    if ctx.ident is not None:
        return _identified(ctx, "gain_fluctuation")
    score, where = _best(ctx, ("corr_z",), absolute=True)
    return _with_fit(ctx, "gain_fluctuation", score, _layers_where(ctx, ("corr_z",)),
                     _line(where, score, " (fluctuation shared by the neurons)"))


def rule_time(ctx):
    if ctx.ident is not None:
        return _identified(ctx, "time_drift")
    score, where = _best(ctx, ("time_z",), absolute=True)
    return _with_fit(ctx, "time_drift", score, _layers_where(ctx, ("time_z",)),
                     _line(where, score, " (a trend in the acquisition time)"))


def rule_fitted_only(cls):
    """A class the identification tests (gain_error, correlated_noise); without it only a fitted
    effect of the class speaks for it."""
    def rule(ctx):
        if ctx.ident is not None:
            return _identified(ctx, cls)
        return _with_fit(ctx, cls, 0.0, [], "")
    rule.__name__ = f"rule_{cls}"
    return rule


def rule_level(ctx):
    """A layer whose own noise level differs from the jointly fitted one, and which passes its
    one-step check at its own level (its level is all that is wrong there)."""
    if ctx.ident is not None:
        # a layer whose noise grows with its signal has no one level: its level is not the evidence
        signal = {r["layer"] for c in ("input_dependent_noise", "gain_fluctuation") for r in _significant(ctx, c)}
        return _identified(ctx, "noise_level", exclude=signal)
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


#: class -> rule (reference §6's classes)
RULES = {
    "noise_level": rule_level,
    "noise_law": rule_law,
    "input_dependent_noise": rule_input_dependent,
    "gain_fluctuation": rule_gain,
    "time_drift": rule_time,
    "correlated_noise": rule_fitted_only("correlated_noise"),
    "gain_error": rule_fitted_only("gain_error"),
    "weight_error": rule_weight,
    "bias_offset": rule_bias,
    "activation_mismatch": rule_activation,
    "readout_nonlinearity": rule_readout,
    # the lag test of lab/_memory.py (a layer's shots depend on the shot acquired before)
    "memory": rule_fitted_only("memory"),
}
assert set(RULES) == set(MECHANISMS), "every reference §6 class has a rule"


class FitGains(dict):
    """{class: z} of :func:`fit_gains`, with ``notes``: sentences naming what a refused offset
    family singles out (a neuron unlike the rest), which :func:`mechanisms` adds to the evidence."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self.notes = {}


def fit_gains(ranking, base_cmp, prior=None, alpha: float = 0.01, share: float = 0.5) -> dict:
    """{class: z}: for each class with a moment-fitted candidate that passes its held-out test or
    removes at least ``share`` of the baseline's excess over the noise floor, how far (in the
    baseline's sd of Q) its discrepancy fell below the baseline's. A candidate that removes
    less is no evidence for its class (an extra parameter absorbs part of any misfit); an
    offset family counts only when it passes, the data identify its values and they look like
    its own effect (``prior``: model -> :func:`~gift_theory.lab._offset_prior.prior_check` rows on
    the fitting half; None skips that check): with
    hundreds of free values it lowers the discrepancy whatever the physics. Weight offsets that
    pass but are refused only as coupled to the programmed weights (``w_structure``,
    ``w_coupling``) are a structured weight error: they count for ``weight_error``."""
    from ._offset_kinds import fitted_as_offsets
    from ._offset_prior import refusing

    out = FitGains()
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
            for r in refused:
                if r["test"].endswith("_outlier"):  # the neuron the offsets single out, named
                    out.notes[f"{c.effects[0]}@{r['layer']}"] = (
                        f"the fitted {c.effects[0]} values of layer {r['layer']} single out {r['neuron']} "
                        f"({r['value']:+.3g}; Grubbs p = {r['p']:.2g} against N(0, e^2) offsets)")
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
    """The ranked mechanism classes the evidence points to, each ``{mechanism, layers, score,
    evidence, p_value}`` (reference §6): with an identification, those its tests name
    (:func:`named`); without one, those whose score exceeds :data:`THRESHOLD`. Best first: by
    score, except that a fluctuating gain goes before the trend its path leaves (:func:`_fluctuation_before_trend`),
    a noise growing with the signal before the levels it raises (:func:`_signal_before_level`)
    and, without taps, the map classes whose candidate mechanism reproduces the output's mean
    lead the other map classes (:func:`~gift_theory.lab._explain_output.order_map_classes`)."""
    out = []
    for cls, rule in RULES.items():
        r = rule(ctx)
        if r is None:
            continue
        score, layers, text = r[:3]
        p = r[3] if len(r) > 3 else float(stats.norm.sf(score)) if np.isfinite(score) else 1.0
        # with an identification: its tests name the class (:func:`named`, so p < ALPHA);
        # without one: the evidence stands THRESHOLD standard deviations out
        listed = p < ALPHA if len(r) > 3 else bool(np.isfinite(score) and score > THRESHOLD)
        if listed:
            out.append({"mechanism": cls, "layers": sorted(int(l) for l in layers), "score": float(score),
                        "evidence": text, "p_value": float(p)})
    out.sort(key=lambda m: -m["score"])
    out = _fluctuation_before_trend(ctx, out)
    out = _wander_before_gain(ctx, out)  # a wander read before a gain (lab/_time.py)
    out = _signal_before_level(ctx, out)
    if ctx.ident is not None and not ctx.taps and getattr(ctx.ident, "output_candidates", ()):
        out = order_map_classes(out, ctx.ident.output_candidates)
    notes = getattr(ctx.fit_gain, "notes", {})
    if notes and out:
        out[0]["evidence"] += "; " + "; ".join(notes.values())
    return out


def _fluctuation_before_trend(ctx, out: list) -> list:
    """A gain that fluctuates on a time scale shorter than the campaign (an AR(1) laser) has a
    realised path with a trend: the within-input trend test then rejects harder (more shots
    inform a trend) than the shared-gain covariance test. When the strongest time_drift test is
    such a gain trend and it carries less than :data:`TREND_SHARE` of the gain's variance the
    covariance measures, gain_fluctuation goes before time_drift (both stay listed): the
    mechanism is the one that carries the variance."""
    pair = _out_of_order(ctx, out, "gain_fluctuation", "time_drift")
    if pair is None:
        return out
    rows = _significant(ctx, "time_drift")
    best = max(rows, key=lambda r: r["z"]) if rows else None
    if best is None or best.get("share") is None or best["share"] >= TREND_SHARE:
        return out
    return _put_before(out, *pair, f"; the time trend carries {best['share']:.0%} of the gain's variance within "
                                    "the inputs' shots: the gain fluctuates")


#: a layer's fixed gain is read as its wandering gain's mean over the campaign when it is within
#: this many rms of the wander's path
WANDER_SPAN = 3.0
#: the tests that read a fixed gain of a layer: W_eff = g W, or z scaled as a whole (an
#: activation's slope on a hidden layer, a readout's gain on the output)
_GAIN_TESTS = {("gain_error", "gain"), ("activation_mismatch", "transfer"), ("readout_nonlinearity", "transfer")}


def _wander_before_gain(ctx, out: list) -> list:
    """A gain that wanders over the campaign (time_drift by the wander test of
    :mod:`~gift_theory.lab._time`) has a mean over this campaign, and that mean is a gain of the
    layer too: a wandering laser's gain was named gain_error first (W_eff = 1.05 W, the path's rms
    0.037), and on a hidden layer an activation's slope. When every class listed before
    time_drift is such a fixed gain -- each of its named tests a gain or a scaled z, at a layer
    whose gain wanders, within :data:`WANDER_SPAN` rms of the path -- time_drift goes before
    them (all stay listed): the gain is what the wander averages to."""
    names = [m["mechanism"] for m in out]
    if ctx.ident is None or "time_drift" not in names:
        return out
    i_t = names.index("time_drift")
    rms = {}
    for r in _significant(ctx, "time_drift"):
        if r["test"] == "wander":
            rms[r["layer"]] = max(rms.get(r["layer"], 0.0), float(r.get("path_rms", 0.0)))
    if not rms or i_t == 0:
        return out
    for m in out[:i_t]:
        rows = _significant(ctx, m["mechanism"])
        if not rows or not all((r["class"], r["test"]) in _GAIN_TESTS and r["layer"] in rms
                               and abs(r["effect"]) <= WANDER_SPAN * rms[r["layer"]] for r in rows):
            return out
    return _put_before(out, i_t, 0, f"; the gain of layer(s) {', '.join(map(str, sorted(rms)))} wanders over the "
                                    f"campaign, and the fixed gain read there is within {WANDER_SPAN:g} rms of its path")


def _signal_before_level(ctx, out: list) -> list:
    """A noise whose variance grows with the signal raises a layer's mean level: the layers'
    levels then differ though the noise at zero signal is the same everywhere. The levels test
    leaves out the layers whose input-dependence test rejects after correction; when one of the
    layers it still names has that test below :data:`ALPHA` unadjusted (too weak to be named,
    strong enough to raise the level), input_dependent_noise goes before noise_level (both stay
    listed). Weighted-sum noise s (1 + beta |u|) in every hidden layer was named noise_level
    first, its layer 1 at level 0.051 against the output's 0.041 (the chip's s) with its
    input-dependence at p = 0.001 unadjusted."""
    pair = _out_of_order(ctx, out, "input_dependent_noise", "noise_level")
    if pair is None:
        return out
    level_layers = set(out[pair[1]]["layers"])
    weak = sorted({int(r["layer"]) for r in ctx.rows if r["class"] == "input_dependent_noise"
                   and r["p"] < ALPHA and r["layer"] in level_layers})
    if not weak:
        return out
    return _put_before(out, *pair, f"; it raises the mean noise level of layer(s) {', '.join(map(str, weak))} too "
                                    f"(input dependence there at unadjusted p < {ALPHA:g})")


def _out_of_order(ctx, out: list, first: str, second: str):
    """``(i_first, i_second)`` when both classes are listed (with an identification) and
    ``first`` comes after ``second``, else None."""
    names = [m["mechanism"] for m in out]
    if ctx.ident is None or first not in names or second not in names:
        return None
    i1, i2 = names.index(first), names.index(second)
    return (i1, i2) if i1 > i2 else None


def _put_before(out: list, i_move: int, i_target: int, note: str) -> list:
    """``out`` with entry ``i_move`` (after ``i_target``) moved just before ``i_target``, ``note``
    added to its evidence."""
    moved = dict(out[i_move], evidence=out[i_move]["evidence"] + note)
    rest = [m for i, m in enumerate(out) if i != i_move]
    return rest[:i_target] + [moved] + rest[i_target:]


def lead_with_explanation(mechs: list, top, base_cmp) -> list:
    """When a fitted model explains the data (``top``: ranking[0], its held-out test passed and
    its values checked), its classes that ``mechs`` lists lead, each scored at least the fit's
    gain in baseline standard deviations (so "best first" holds by score too); the rest keep
    their order. A passing fit and an identification test rejecting for the same class are two
    measurements agreeing -- without taps a gain on every layer folds into the output's map as
    shifts and a general change, and mesh insertion loss was named bias_offset first while
    layer_gain passed at p = 0.5 and gain_error's own test rejected. A class the identification
    does not list is not added: a fit that passes is not proof (a bias drifting in time passed
    as layer_gain without taps, p = 0.09, while time_drift's test rejected)."""
    if top is None:
        return list(mechs)
    classes = list(dict.fromkeys(REGISTRY[e].mechanism for e in top.effects))
    unit = base_cmp.se if base_cmp.se > 0 else 1.0
    gain = float((base_cmp.discrepancy - top.comparison.discrepancy) / unit)
    fit_text = (f"awgn + {' + '.join(top.effects)} explains the data (held-out p = {top.comparison.p_value:.3g}), "
                f"lowering the discrepancy by {gain:.1f} sd")
    lead = []
    for cls in classes:
        for m in mechs:
            if m["mechanism"] == cls:
                lead.append(dict(m, evidence=fit_text + "; " + m["evidence"], score=max(float(m["score"]), gain)))
    return lead + [m for m in mechs if m["mechanism"] not in classes]
