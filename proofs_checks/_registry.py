"""The registry of check ids (reference §5, then the ids appended by issues 12 and 27) and the runner."""

from __future__ import annotations

import sys
import time
from typing import Callable

import jax

from . import _gift, _kushner, _linear, _sampling, _sampling_proofs, _sgd, _symbolic, _taylor, _theorem1
from ._record import SHARES

#: id -> check function ``(key=None, precise=False) -> record``; the first twelve are reference §5
CHECKS: dict[str, Callable] = {
    "lemma_gaussian_product_derivative": lambda key=None, precise=False: _symbolic.lemma_gaussian_product_derivative(
        max_L=4 if precise else 3),
    "backprop_formulas": lambda key=None, precise=False: _symbolic.backprop_formulas(
        (2, 3, 2, 2) if precise else (2, 2, 2, 1)),
    "score_function_identity": lambda key=None, precise=False: _symbolic.score_function_identity(
        (((1, 1, 1), "quadratic"), ((1, 2, 1), "identity")) + ((((2, 1, 1), "quadratic"),) if precise else ())),
    "d0_limit": _sampling.d0_limit,
    "hierarchical_sampling": _sampling.hierarchical_sampling,
    "sgd_limit_points": _sgd.sgd_limit_points,
    "square_integrability": _sampling.square_integrability,
    "theorem1_condition": _theorem1.theorem1_condition,
    "theorem1_conclusion": _theorem1.theorem1_conclusion,
    "theorem2_guarantee": _gift.theorem2_guarantee,
    "linear_example_bound": _linear.linear_example_bound,
    "gift_never_worse": _gift.gift_never_worse,
    # appended (issue 12): claims that were not checked
    "algorithm1_stopping_rule": _gift.algorithm1_stopping_rule,
    "proposition1_ode_limit": _sgd.proposition1_ode_limit,
    "hierarchical_borel_cantelli": _sampling_proofs.hierarchical_borel_cantelli,
    "d0_covariance_identity": _sampling_proofs.d0_covariance_identity,
    "gift_taylor_rule": _taylor.gift_taylor_rule,
    "linear_example_text_claim": _linear.linear_example_text_claim,
    # appended (issue 27): claims that were not checked
    "proposition2_unique_point": _kushner.proposition2_unique_point,
    "kushner_verification": _kushner.kushner_verification,
    "linear_example_v_scaling": _linear.linear_example_v_scaling,
}

CHECK_IDS = tuple(CHECKS)
assert len(CHECK_IDS) <= SHARES, "each check owns one share of the family-wise error level"


def run_checks(ids=None, *, precise: bool = False, seed: int = 0, log=None) -> list[dict]:
    """Run the checks ``ids`` (all by default) in float64; one reference §4 record each.

    A check that raises is reported as "inconclusive" with the error as evidence (the run
    goes on). ``log`` (default stderr) receives one progress line per check.
    """
    from ._record import decide, record

    log = sys.stderr if log is None else log
    ids = CHECK_IDS if ids is None else tuple(ids)
    out = []
    key = jax.random.PRNGKey(seed)
    for cid in ids:
        t = time.perf_counter()
        try:
            with jax.enable_x64(True):
                # each check's key depends on its id and the seed only (not on which checks run)
                rec = CHECKS[cid](key=jax.random.fold_in(key, CHECK_IDS.index(cid) + 1), precise=precise)
        except Exception as exc:  # a crashed check decides nothing
            rec = record(cid, "(check did not run)", decide(), f"the check raised {type(exc).__name__}: {exc}")
        rec["seconds"] = round(time.perf_counter() - t, 2)
        log.write(f"gift check: {cid}: {rec['verdict']} ({rec['seconds']:.1f} s)\n")
        log.flush()
        out.append(rec)
    return out
