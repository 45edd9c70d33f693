"""The ranking of the candidates (reference §6): which are fitted (the flagged classes first),
their order (passes, refused, fails; by penalised score, then discrepancy; ties by name), the
greedy second step on top of the best one, and the alternatives the output's means allow."""

from __future__ import annotations

import sys

from ..effects import REGISTRY
from ._level import ALPHA
from ._results import STATUSES, Candidate, _status
from ._session import Session
from ._verdict import (
    first_refusal,
    found_reproduced_rule,
    identification_refusals,
    mechanism_classes,
    unmoved_tails_rule,
    unreproduced_correlations_rule,
)


def _log(msg, verbose):
    if verbose:
        sys.stderr.write(msg + "\n")
        sys.stderr.flush()


def rank_key(c: Candidate):
    """The order of the ranking (reference §6): those that pass, then the refused ones, then those
    the data reject; among those that pass by penalised score (the parsimony of reference §4),
    among the others by held-out discrepancy; ties by name (the order never depends on the
    order the candidates were scored in)."""
    status = _status(c)
    within = c.score if status == "passes" else c.comparison.discrepancy
    return (STATUSES.index(status), within, c.name)


def ranked(cands) -> list:
    """``cands`` in the ranking's order (:func:`rank_key`)."""
    return sorted(cands, key=rank_key)


def search_key(c: Candidate):
    """The greedy second step's order: the candidates that pass their test first, each group by
    penalised score (a failing per-device offset family with hundreds of effective parameters
    must not become the first effect a pair is built on), ties by name."""
    return (c.comparison.p_value < ALPHA, c.score, c.name)


def _merge_second_stage(first: Candidate, stage2: list, singles: list) -> list:
    """Every candidate after the greedy second step, in the ranking's order: the pairs, the first
    effect, and the singles not tried on top of it (a runner-up tried on top of the first is
    listed as the pair only)."""
    named = {c.effects[-1] for c in stage2}
    return ranked(list(stage2) + [first] + [c for c in singles if c.effects[0] not in named])


def _compatible(first: Candidate, name: str) -> bool:
    """``name`` can be added on top of ``first``: not already there, not a second noise law."""
    if name in first.effects:
        return False
    laws = [e for e in first.effects if REGISTRY[e].stage == "law"]
    return not (laws and REGISTRY[name].stage == "law")


#: runners-up fitted on top of a failing first effect (the greedy second step)
SECOND = 4


def flagged_classes(ident) -> dict:
    """``{class: smallest Holm-adjusted p}`` of the identification's tests that reject at 0.01: the
    mechanism classes the closed-form identification sees in the data."""
    out: dict = {}
    for row in ([] if ident is None else ident.rows()):
        if row.get("p_adj", 1.0) < ALPHA:
            out[row["class"]] = min(out.get(row["class"], 1.0), float(row["p_adj"]))
    return out


def _single(name: str) -> tuple:
    effects = tuple(name.split("+"))
    return effects, None, effects, effects


def rank_candidates(session: Session, names, second, verbose: bool, ident=None, progress=None) -> tuple[list, list]:
    """The candidates fitted, scored, checked and ranked; a second stage on top of the best one
    when every one still fails (see :func:`diagnose`). Returns ``(ranking, not_fitted)``.

    First the candidates of a class the identification flags (:func:`flagged_classes`) are
    fitted; when one of them passes every check, the others are not fitted (the identification
    clears their classes, and an explanation has been found) and are listed in ``not_fitted``
    with that reason. Otherwise every candidate is fitted."""
    def fitted(specs):
        return identification_refusals(session.candidates(specs, progress), ident, session.baseline_comparison,
                                       law, found)

    law = first_refusal(unmoved_tails_rule(session, ident), unreproduced_correlations_rule(session, ident))
    found = found_reproduced_rule(session, ident)

    flagged = flagged_classes(ident)
    # the built-in memory is fitted only where the lag test names memory (through each
    # input's shots a memory is a shift and an excess variance per neuron, which the held-out test
    # cannot tell from other physics; lab/_memory.py)
    quiet = ident is not None and "memory" not in flagged and "memory" in names and len(names) > 1
    names = [n for n in names if not (quiet and n == "memory")]
    first = [n for n in names if mechanism_classes(n) & set(flagged)]
    rest = [n for n in names if n not in first]
    todo = first if first and rest else list(names)
    ranking = fitted([_single(n) for n in todo])
    not_fitted = []
    if todo is first:
        if any(c.status == "passes" for c in ranking):
            not_fitted = [{"effect": n, "mechanism": "+".join(sorted(mechanism_classes(n))),
                           "reason": "the identification clears its class (no test of it rejects at 0.01) and "
                                     "awgn + " + " + ".join(min((c for c in ranking if c.status == "passes"),
                                                               key=rank_key).effects)
                                     + " passes every check"} for n in rest]
        else:
            ranking += fitted([_single(n) for n in rest])
            todo = first + rest
    if quiet:
        not_fitted.append({"effect": "memory", "mechanism": "memory",
                           "reason": "the identification's lag test names no memory at Holm-adjusted 0.01"})
    for name, cand in zip(todo, ranking):
        _log(f"  + {name:<15s} {cand.model.describe():<60s} discrepancy {cand.comparison.discrepancy:.3g} "
             f"p = {cand.comparison.p_value:.3g} [{cand.status}] ({cand.seconds:.1f} s)", verbose)
    if not_fitted:
        _log(f"  not fitted (the identification clears their classes): {', '.join(r['effect'] for r in not_fitted)}",
             verbose)
    ranking.sort(key=search_key)
    if (second != 0 and len(ranking) > 1 and not any(_status(c) == "passes" for c in ranking)
            and (ranking[0].comparison.p_value < ALPHA or ranking[0].lacks)):
        # none passes, and the best fails its test or is refused for something the identification
        # finds that it has no term for (multiplicative noise, refused by rule g on
        # multiplicative + common-mode noise): the runners-up, each on top of it
        first = ranking[0]
        rest = [c.effects[0] for c in ranking[1:] if _compatible(first, c.effects[0])][:second]
        # on top of the first's fitted model; but a first refused for what it lacks is refitted
        # with each runner-up jointly: its fit gave the missing effect's share to its own
        # parameter (per-neuron multiplicative noise took the shared gain's variance, and
        # common_mode fitted on top of it went to c = 1e-6)
        joint = first.status == "refused" and first.lacks
        stage2 = fitted([(first.effects + (name,), None if joint else first.model,
                          first.effects + (name,) if joint else (name,), first.effects + (name,)) for name in rest])
        for cand in stage2:
            _log(f"  + {'+'.join(cand.effects):<30s} {cand.model.describe():<60s} discrepancy "
                 f"{cand.comparison.discrepancy:.3g} p = {cand.comparison.p_value:.3g}", verbose)
        return _merge_second_stage(first, stage2, ranking[1:]), not_fitted
    return ranked(ranking), not_fitted


def with_alternatives(session: Session, ranking: list, not_fitted: list, ident, verbose: bool, progress=None):
    """Reference §8: without taps, when ranking[0] passes and the output's candidate
    mechanisms (:mod:`._explain_output`) say the output's mean is reproduced as well by classes
    of another group, the candidates of those classes left unfitted are fitted too, so the
    verdict can say when the data cannot choose between them (:mod:`._ambiguity`). Among models
    the data cannot tell apart, the one whose class the identification flags keeps the lead; one
    better by more than the ambiguity's margin leads. Returns ``(ranking, not_fitted)``."""
    from ._ambiguity import APART
    from ._explain_output import MAP_CLASSES, _group

    if ident is None or ident.taps or not ranking or ranking[0].status != "passes" or not not_fitted:
        return ranking, not_fitted
    top = ranking[0]
    mine = {_group(c) for c in mechanism_classes("+".join(top.effects))}
    also = {c.mechanism for c in getattr(ident, "output_candidates", ()) if c.explains
            and c.mechanism in MAP_CLASSES and _group(c.mechanism) not in mine}
    extra = [r["effect"] for r in not_fitted if mechanism_classes(r["effect"]) & also]
    if not extra:
        return ranking, not_fitted
    _log(f"  also fitted (the output's mean is reproduced as well by {', '.join(sorted(also))}): "
         f"{', '.join(extra)}", verbose)
    new = identification_refusals(session.candidates([_single(n) for n in extra], progress), ident,
                                  session.baseline_comparison)
    out = ranked(list(ranking) + new)
    unit = session.baseline_comparison.se if session.baseline_comparison.se > 0 else 1.0
    if out[0] is not top and out[0].status == "passes" and top.score - out[0].score < APART * unit:
        out = [top] + [c for c in out if c is not top]
    return out, [r for r in not_fitted if r["effect"] not in extra]
