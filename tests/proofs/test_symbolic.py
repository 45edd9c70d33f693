"""Symbolic layer: lem:chain-derivative, backprop formulas, the score identity."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import sympy as sp
from hypothesis import given
from hypothesis import strategies as st

from proofs_checks import _symbolic as S


def test_lemma_printed_fails_corrected_holds():
    for L in (1, 2):
        assert S.lemma_difference(L)[0] != 0
        assert S.lemma_difference(L, corrected=True)[0] == 0
    r = S.lemma_gaussian_product_derivative(max_L=2)
    assert r["verdict"] == "fails" and r["correction"] and r["counterexample"]["relative_difference_(lhs-rhs)/prod"] != 0


@given(dims=st.lists(st.integers(1, 6), min_size=1, max_size=4), s=st.floats(0.05, 5.0),
       seed=st.integers(0, 2 ** 31 - 1))
def test_lemma_numeric_random_dimensions(dims, s, seed, x64):
    """d/ds log prod phi_s(n_i) by autodiff equals the corrected factor, for random dimensions."""
    rng = np.random.default_rng(seed)
    ns = [jnp.asarray(rng.normal(size=d) * s) for d in dims]

    def logprod(s_):
        return sum(-0.5 * n.size * jnp.log(2 * jnp.pi * s_ ** 2) - jnp.sum(n ** 2) / (2 * s_ ** 2) for n in ns)

    auto = float(jax.grad(logprod)(s))
    factor = sum(float(jnp.sum(n ** 2)) / s ** 2 - n.size for n in ns)
    assert math.isclose(auto, factor / s, rel_tol=1e-9, abs_tol=1e-9)
    if abs(s - 1) > 1e-3 and abs(factor) > 1e-6:
        assert not math.isclose(auto, factor, rel_tol=1e-6)       # the printed form


def test_backprop_holds_and_broken_variant_fails():
    assert S.backprop_difference((2, 2, 1)) == []
    assert len(S.backprop_difference((2, 2, 1), printed=False)) > 0   # dropping sigma' is detected
    assert S.backprop_formulas((1, 2, 1))["verdict"] == "holds"


def test_score_identity_ratio_is_minus_s_over_2():
    res = S.score_identity_difference((1, 1, 1), activation="identity")
    s = res["s"]
    for t, p, c in zip(res["true"], res["printed"], res["corrected"]):
        assert sp.expand(t - c) == 0
        if sp.expand(t) != 0:
            assert sp.simplify(p / t + s / 2) == 0
    r = S.score_function_identity((1, 1, 1), activation="identity")
    assert r["verdict"] == "fails" and r["correction"]


@pytest.mark.slow
def test_score_identity_beyond_one_neuron_per_layer():
    r = S.score_function_identity((((1, 1, 1), "quadratic"), ((1, 2, 1), "identity")))
    assert r["verdict"] == "fails" and r["correction"] and "1-2-1" in r["evidence"]
    assert all(h["verified"] is True for h in r["hypotheses"])
