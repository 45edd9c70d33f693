"""Sampling lemmas: the hierarchical variance formula, the fourth-moment stabiliser on
square-integrable and on heavy-tailed samples (the D^[0] constant: test_checks.test_d0_limit)."""

import math

import jax
import numpy as np

from proofs_checks import _sampling as S


def test_hierarchical_variance_formula():
    K1, K2, R = 8, 4, 20000
    Sm, dev = S.hierarchical_toy(jax.random.PRNGKey(0), K1, K2, R)
    assert abs(Sm.mean() - 2.0) < 4.5 * Sm.std() / math.sqrt(R)
    for samples, formula in ((Sm, 2 / K1 + 6 / (K1 * K2)), (dev, 6 / (K1 * K2))):
        c = (samples - samples.mean()) ** 2
        assert abs(c.mean() - formula) < 4.5 * c.std() / math.sqrt(R)
    # the i.i.d. rate Var(f)/(K1 K2) is not the hierarchical variance
    assert S._var_test(Sm, 8 / (K1 * K2))[0] == "fails"


def test_fourth_moment_stabiliser_known_cases():
    rng = np.random.default_rng(1)
    q = rng.standard_normal(2 ** 15) ** 4
    qb = q.reshape(8, -1)
    v, *_ = S.stabilises(qb.mean(1), qb.std(1, ddof=1) / math.sqrt(qb.shape[1]))
    assert v == "holds"
    q = rng.standard_cauchy(2 ** 15) ** 4          # no finite moment at all
    qb = q.reshape(8, -1)
    v, *_ = S.stabilises(qb.mean(1), qb.std(1, ddof=1) / math.sqrt(qb.shape[1]))
    assert v != "holds"
