"""Intervals on fitted parameters (CONTRACTS §4 "intervals", gift_theory/lab/_intervals.py).

The profile interval of an offset scale is checked for coverage on its own model (synthetic
offsets and measurement errors, plain numpy: the binomial count over 400 sets against its
nominal 95 % within 4.5 binomial standard errors); the sandwich interval of a moment fit is
checked for its form and for covering the truth on a small simulated file; the coverage on the
full pipeline is the study ``python -m studies.intervals`` (docs/plugins.md section 8)."""

import math

import jax
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.lab import fit_effects, simulate_measurement
from gift_theory.lab import fit_uncertainty
# private: the profile interval's coverage on its own model, apart from the fit feeding it
from gift_theory.lab._intervals import scale_interval

Z = 4.5


def test_scale_interval_covers_at_its_level():
    """d_i = delta_i + eps_i, delta_i ~ N(0, e^2) (the device), eps_i ~ N(0, w_i) (each value's
    error, known): in whitened form the pairs (d2, c2) = (1 / w_i, d_i^2 / w_i); the interval of
    e covers the true e in 95 % of the sets."""
    rng = np.random.default_rng(0)
    sets, n = 400, 28
    hits = 0
    for _ in range(sets):
        e = rng.uniform(0.03, 0.15)
        w = rng.uniform(0.01, 0.04, n) ** 2
        d = rng.normal(0.0, e, n) + rng.normal(0.0, np.sqrt(w))
        lo, hi = scale_interval(1.0 / w, d * d / w)
        assert 0.0 <= lo <= hi
        hits += lo <= e <= hi
    p = hits / sets
    assert abs(p - 0.95) < Z * math.sqrt(0.95 * 0.05 / sets), p


def test_scale_interval_edges():
    # offsets no bigger than their errors: e = 0 is inside, the lower end is 0
    lo, hi = scale_interval(np.full(20, 1e4), np.full(20, 0.5))
    assert lo == 0.0 and 0.0 < hi < 0.05
    # no information at all
    assert scale_interval(np.zeros(3), np.ones(3)) == (0.0, math.inf)


@pytest.fixture(scope="module")
def shot_file():
    arch = gt.Architecture((5, 8, 6, 3))
    params = gt.init_params(jax.random.PRNGKey(3), arch, gain=1.5)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(4), (48, 5)), np.float64)
    physics = gt.Physics.create(s=0.05, shot=0.02)
    return simulate_measurement(jax.random.PRNGKey(5), params, x, physics, shots=24, taps=True)


@pytest.mark.slow
def test_every_fitted_scalar_has_an_interval_around_its_estimate(shot_file):
    key = jax.random.PRNGKey(0)
    res = fit_effects(key, shot_file, ["shot"])
    unc = fit_uncertainty(key, shot_file, res.after, B=12)
    params = res.after.params_json()
    assert set(unc["intervals"]) == {"s", "q"}
    for p, (lo, hi) in unc["intervals"].items():
        assert 0.0 < lo < params[p] < hi, (p, lo, params[p], hi)
        assert "sandwich" in unc["interval_method"][p]
    assert unc["per_neuron"] == {} and unc["per_neuron_se"] == {}
    # same key, same numbers
    again = fit_uncertainty(key, shot_file, res.after, B=12)
    assert again["intervals"] == unc["intervals"]
