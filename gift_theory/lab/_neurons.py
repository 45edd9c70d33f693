"""Per-neuron explanations: a model whose per-neuron values the data identify is an explanation.

A per-neuron parameter (``shape = {"p": "neurons"}``, reference §2b) is fitted like a per-device
offset family, with a ridge prior whose scale is fitted too; the verdict's rules a and b were
written for offsets drawn as N(0, e^2): rule a refuses a family whose effective degrees of
freedom are under half its values, rule b one whose values hold a gross outlier. A plugin's
per-neuron value is not such a draw: a transmission of 0.003 among values of 0.99-1.00 is the
finding (a dead neuron), not a sign that the values are noise.

**The rule** (docs/reference.md §8). When every offset family a model fits is a per-neuron
parameter (not ``weight_error``'s weights, not ``bias_offset``'s biases, whose prior is their
physics), the model's values are *identified neuron by neuron* when each value has a finite
standard error (its interval, reference §2b ``per_neuron_se``) at most :data:`SE_SHARE` of the
family's prior scale -- its posterior variance at most half the prior's: the data, not the
prior, set it (the per-value form of rule a's half). Such a model is not refused by rule a, nor
by rule b's outlier test on those values; its other checks stand, and if it passes it explains
the data, the neurons that stand out named.
"""

from __future__ import annotations

import math

import numpy as np

from ..effects import REGISTRY

#: a value is identified when its standard error is at most this share of its family's prior scale
SE_SHARE = 1.0 / math.sqrt(2.0)


def per_neuron_families(model) -> list[tuple[str, str]]:
    """(effect, parameter) of every per-neuron parameter the model fits; [] when it also fits
    offsets of another kind (weights, biases) or none at all."""
    out = []
    for name in model.offsets:
        cls = REGISTRY.get(name)
        if cls is None:
            return []
        if getattr(cls, "offsets_of", None):
            return []
        out += [(name, p) for p, k in getattr(cls, "shape", {}).items() if k == "neurons"]
    return out


def identified(model) -> tuple[bool, str]:
    """``(ok, sentence)``: whether the model's per-neuron values are identified by the rule of the
    module (False with no such values, or offsets of another kind)."""
    fams = per_neuron_families(model)
    if not fams:
        return False, ""
    from ._intervals import per_neuron_json

    pj = per_neuron_json(model)
    worst, count = 0.0, 0
    for name, p in fams:
        vals, ses = pj["per_neuron"].get(p), pj["per_neuron_se"].get(p)
        if not vals or not ses:
            return False, ""
        scale = float(model.offsets.get(name, 0.0))
        if not scale > 0:
            spread = np.concatenate([np.asarray(v, float) for v in vals.values()])
            scale = float(np.std(spread)) if spread.size > 1 else 0.0
        for l, row in ses.items():
            for se in row:
                if se is None or not np.isfinite(se) or not scale > 0:
                    return False, ""
                worst = max(worst, float(se) / scale)
                count += 1
    if worst > SE_SHARE:
        return False, ""
    return True, (f"its {count} per-neuron values are identified neuron by neuron (each standard error at most "
                  f"{worst:.2f} of the prior scale, the rule's {SE_SHARE:.2f})")


def outlier_tests(model) -> set:
    """The prior checks' outlier tests of the model's per-neuron families ("<param>_outlier")."""
    return {f"{p}_outlier" for _, p in per_neuron_families(model)}
