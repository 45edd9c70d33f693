"""What the lab returns: a candidate (one fitted extension of the model, scored and checked),
its status and penalised score, and the results of :func:`~gift_theory.lab.diagnose` and
:func:`~gift_theory.lab.fit_effects` with their JSON (reference §4, §6)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..effects import REGISTRY
from . import _ambiguity
from ._compare import Comparison
from ._level import ALPHA
from ._shots import Model
from ._verdict import as_json_fields


#: a candidate's status (reference §6), in ranking order
STATUSES = ("passes", "refused", "fails")


def n_scalar_params(name: str, arch) -> int:
    """The scalar parameters effect ``name`` adds to a model: one per parameter, a per-layer one
    (``shape = "layers"``) once per layer of its scope."""
    cls = REGISTRY[name]
    n = 0
    for p in cls.params:
        if cls.shape.get(p) == "layers":
            n += sum(1 for l in range(1, arch.depth + 1) if cls.acts_on(cls, l, arch.depth))
        else:
            n += 1
    return n


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One fitted extension of the model, scored on held-out inputs.

    n_free : the parameters it adds, an offset family counted by its effective degrees of freedom
    nominal : the parameters it adds, every offset counted as one
    status : ``"passes"``, ``"refused"`` or ``"fails"`` (see the module); empty until checked
    refused_because : why a candidate that passes its test is not an explanation (status refused)
    refused_for : the name of the rule behind each sentence of ``refused_because``, in its order
        (``"keep"``, ``"identified"``, ``"prior"``, ``"time_free_twin"``, ``"one_step"``, an
        identification rule's function name, ``"shots"``, ``"not_reproduced"``): what the code
        reads, where the sentences are what a user reads
    lacks : refused (also) for something the identification finds that it has no term for (rules
        b'', b''', e, f, g): a second effect on top of it may be what is missing
    bought_by : when it buys its keep by what the identification found rather than on the
        held-out half (:func:`~gift_theory.lab._verdict.found_reproduced_rule`), the sentence
        saying so
    """

    effects: tuple
    model: Model
    comparison: Comparison
    score: float
    seconds: float
    n_free: float = 0.0
    nominal: int = 0
    status: str = ""
    refused_because: tuple = ()
    refused_for: tuple = ()
    lacks: bool = False
    bought_by: str = ""

    @property
    def name(self) -> str:
        return "+".join(self.effects)

    def mechanism(self) -> str:
        return "+".join(REGISTRY[e].mechanism for e in self.effects)

    def as_json(self) -> dict:
        # a second-stage entry is named by the effect it adds; "with" lists the ones before
        out = {"effect": self.effects[-1], "mechanism": self.mechanism(), "status": self.status,
               "discrepancy_after": self.comparison.discrepancy, "p_value_after": self.comparison.p_value,
               "params": self.model.params_json(), "se": self.comparison.se, "score": self.score,
               "n_free": self.n_free, "nominal_params": self.nominal}
        if len(self.effects) > 1:
            out["with"] = list(self.effects[:-1])
        if self.refused_because:
            out["refused_because"] = list(self.refused_because)
        if self.bought_by:
            out["bought_by"] = self.bought_by
        from ._intervals import per_neuron_json  # reference §2b: per-neuron values and their standard errors
        out.update(per_neuron_json(self.model))
        if self.comparison.replicates:
            out["net_discrepancy_after"] = self.comparison.net_discrepancy
            out["refit_null_replicates"] = self.comparison.replicates
            out["fitted_offsets"] = sorted(self.model.offsets)
        return out


def penalised_score(cmp: Comparison, n_params: float, base: Comparison | None = None) -> float:
    """Held-out discrepancy plus 2 standard deviations per added parameter. The unit is the
    baseline's standard deviation of Q under the model (one scale for every candidate; a
    candidate's own would reward a model whose channels happen to be more correlated)."""
    unit = base.se if base is not None and base.se > 0 else cmp.se
    return float(cmp.discrepancy + 2.0 * unit * n_params)


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`."""

    baseline: Model
    baseline_comparison: Comparison
    ranking: tuple
    one_step: tuple
    held_out: np.ndarray
    seconds: float
    has_taps: bool = False
    signatures: dict = dataclasses.field(default_factory=dict)
    where: dict | None = None
    explained: bool = False
    reasons: tuple = ()
    verdict: str = ""
    failing_layers: tuple | None = None
    mechanisms: tuple = ()
    evidence: tuple = ()
    not_fitted: tuple = ()
    output_explanations: tuple = ()
    #: the verdict names the awgn model itself (it passes and the identification flags nothing):
    #: the JSON ranking then starts with it (reference §6: ranking[0] is what the verdict names)
    names_baseline: bool = False
    #: the models that explain the data, ranking[0] first (reference §8; empty when not explained)
    explained_by: tuple = ()
    #: the candidates the data cannot tell from ranking[0] (:mod:`._ambiguity`)
    ambiguous_with: tuple = ()
    #: the measurement that would tell the hypotheses left standing apart (:mod:`._design`), or None
    next_measurement: dict | None = None

    @property
    def missing_effect_detected(self) -> bool:
        return bool(self.baseline_comparison.p_value < ALPHA)

    def _baseline_entry(self) -> dict:
        """The awgn model as a ranking entry (``"baseline": true``: nothing added to it)."""
        c = self.baseline_comparison
        return {"effect": self.baseline.effects[-1], "mechanism": "+".join(REGISTRY[e].mechanism
                                                                           for e in self.baseline.effects),
                "status": "passes", "baseline": True, "discrepancy_after": c.discrepancy, "p_value_after": c.p_value,
                "params": self.baseline.params_json(), "se": c.se, "score": penalised_score(c, 0.0, c),
                "n_free": 0.0, "nominal_params": 0}

    def as_json(self) -> dict:
        """The reference §4 object of ``gift diagnose --json`` (plus a few extra keys)."""
        c = self.baseline_comparison
        return {"baseline": {"effects": self.baseline.effects, "params": self.baseline.params_json(),
                             "discrepancy": c.discrepancy, "noise_floor": c.noise_floor, "p_value": c.p_value,
                             "se": c.se, "floor_se": c.floor_se, "channel_z": c.as_dict()["channel_z"]},
                "missing_effect_detected": self.missing_effect_detected,
                **as_json_fields(self.explained, self.reasons, self.verdict, self.failing_layers, self.mechanisms),
                "ranking": _ambiguity.mark(([self._baseline_entry()] if self.names_baseline else [])
                                           + [cand.as_json() for cand in self.ranking],
                                           self.ranking[0] if self.ranking else None, self.ambiguous_with),
                "explained_by": list(self.explained_by),
                "next_measurement": _public_design(self.next_measurement),
                "not_fitted": [dict(r) for r in self.not_fitted],
                **({"output_explanations": list(self.output_explanations)} if self.output_explanations else {}),
                "evidence": list(self.evidence),
                "where": list(self.one_step),
                "signatures": self.signatures,
                "worst_cells": [] if self.where is None else self.where["worst"][:10],
                "held_out_inputs": int(len(self.held_out)),
                **({"refit_null_calibrated": self.has_taps} if any(c.comparison.replicates for c in self.ranking)
                   else {}),
                "seconds": self.seconds}


def _public_design(nxt):
    from ._design import public

    return public(nxt)


def _status(c: Candidate) -> str:
    return c.status or ("fails" if c.comparison.p_value < ALPHA else "passes")


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of :func:`fit_effects`: the model before and after adding effects."""

    before: Model
    after: Model
    comparison_before: Comparison
    comparison_after: Comparison
    ladder: tuple  # ((label, Comparison), ...) one rung per added effect
    has_taps: bool = False
    held_out: np.ndarray | None = None  # the inputs scored (indices into the measurement)

    def as_json(self) -> dict:
        """The reference §4 object of ``gift fit --json`` (plus a few extra keys)."""
        a, b = self.comparison_after, self.comparison_before
        return {"effects": self.after.effects, "params": self.after.params_json(),
                "discrepancy_before": b.discrepancy, "discrepancy_after": a.discrepancy,
                "noise_floor": a.noise_floor, "p_value_after": a.p_value,
                "p_value_before": b.p_value, "se_before": b.se, "se_after": a.se, "floor_se": a.floor_se,
                "ladder": [{"model": lab, "discrepancy": c.discrepancy, "se": c.se, "p_value": c.p_value,
                            **({"net_discrepancy": c.net_discrepancy} if c.replicates else {})}
                           for lab, c in self.ladder],
                **({"net_discrepancy_after": a.net_discrepancy, "refit_null_replicates": a.replicates,
                    "refit_null_calibrated": self.has_taps, "fitted_offsets": sorted(self.after.offsets)}
                   if a.replicates else {})}
