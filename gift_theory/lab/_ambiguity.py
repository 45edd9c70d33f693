"""When the data cannot choose: models of different classes that explain the data equally well.

**The rule** (docs/reference.md §8). Two ranking entries are indistinguishable when

1. both pass (status ``"passes"``: the held-out test at 0.01 and every check of the verdict's
   rule, :mod:`._verdict`),
2. their models are of different mechanism classes (§6; for a pair, its set of classes), and
3. their held-out discrepancies differ by less than :data:`APART` baseline standard deviations
   of the discrepancy -- the price of one parameter: what the ranking asks an extra parameter to
   buy, the twin rule (b') asks a trend in time to buy, and so what the data must show to prefer
   one model. The discrepancies, not the ranking's penalised scores: the penalty is the ranking's
   preference for fewer parameters, not evidence in the data (a gain per layer that fits exactly
   as an activation's slope sits 2 sd behind it by its second parameter alone).

When ranking[0] has such peers, the data are explained (``explained`` stays true) by each of
them: the verdict line names them all ("the data cannot tell ... from ..."), ``explained_by``
lists them (ranking[0] first), and each such entry of the ranking carries
``indistinguishable_from`` (the others). The next measurement
(:mod:`._design`) is designed to tell them apart.

Only candidates the diagnosis fitted can be peers: when the candidates of the classes the
identification flags include one that passes, the others are not fitted (``not_fitted``: the
identification clears their classes) and cannot be told apart here.
"""

from __future__ import annotations

from ..effects import REGISTRY

#: two passing models whose penalised held-out discrepancies are closer than this many baseline
#: standard deviations are indistinguishable (the ranking's price of one parameter)
APART = 2.0

#: what differs on the chip, per class, in the words of docs/reference.md §6 (shortened)
WHAT = {
    "noise_level": "the additive noise level",
    "noise_law": "the noise's law",
    "input_dependent_noise": "a noise that grows with the signal",
    "gain_fluctuation": "a gain fluctuating from shot to shot",
    "time_drift": "a parameter drifting over the acquisition",
    "correlated_noise": "a noise shared by a layer's neurons",
    "gain_error": "a fixed gain on a layer's weighted sum",
    "weight_error": "an error of the fixed linear map",
    "bias_offset": "per-neuron shifts of the pre-activation",
    "activation_mismatch": "the activation's shape",
    "readout_nonlinearity": "the readout's transfer",
    "memory": "a memory of the shot acquired before",
}


def classes_of(cand) -> frozenset:
    return frozenset(REGISTRY[e].mechanism for e in cand.effects)


def describe(cand) -> str:
    """``awgn + layer_gain (a fixed gain on a layer's weighted sum)``."""
    what = " and ".join(WHAT.get(c, c) for c in sorted(classes_of(cand)))
    return f"awgn + {' + '.join(cand.effects)} ({what})"


def peers(ranking, base_cmp) -> list:
    """The entries the data cannot tell from ranking[0] by the module's rule (ranking[0] excluded;
    [] when it does not pass)."""
    if not ranking or ranking[0].status != "passes":
        return []
    top = ranking[0]
    unit = base_cmp.se if base_cmp is not None and base_cmp.se > 0 else 1.0
    own = classes_of(top)
    return [c for c in ranking[1:] if c.status == "passes" and classes_of(c) != own
            and abs(c.comparison.discrepancy - top.comparison.discrepancy) < APART * unit]


def sentence(top, others, base_cmp) -> str:
    """The plain sentence the verdict adds: which models, their discrepancies, the rule's margin."""
    unit = base_cmp.se if base_cmp is not None and base_cmp.se > 0 else 1.0
    names = [describe(top)] + [describe(c) for c in others]
    scores = ", ".join(f"{c.comparison.discrepancy:.3g}" for c in [top] + list(others))
    return (f"the data cannot tell {', '.join(names[:-1])} from {names[-1]}: each passes every check, their "
            f"held-out discrepancies ({scores}) are within {APART:g} sd ({APART * unit:.3g}) of each other")


def explained_by(top, others) -> list[str]:
    """Names of the models that explain the data (ranking[0] first), each its effects joined by "+"."""
    return ["+".join(c.effects) for c in [top] + list(others)]


def mark(entries: list, top, others) -> list:
    """The ranking's JSON entries with ``indistinguishable_from`` on each entry of the group."""
    if top is None or not others:
        return entries
    group = explained_by(top, others)
    for e in entries:
        name = "+".join(list(e.get("with", [])) + [e["effect"]])
        if name in group and not e.get("baseline"):
            e["indistinguishable_from"] = [g for g in group if g != name]
    return entries
