"""Without taps: candidate mechanisms put into the model, and which of them explains the
output's mean (gift_theory.lab._explain_output).

The files come from test_identify's plain-numpy simulator (CONTRACTS §1-§2, not gift's forward
pass); the derivative columns are checked against central differences of the propagation
itself, on the same draws.

Private names on purpose: the propagation's derivative columns and the shape polynomials are
numerical kernels; rule e's refusal and the "as well by" list are decided here on hand-made
candidates no cheap simulated file produces, and ``explain`` at a given level is the part of
``identify`` under test. The mechanisms named from the files go through :func:`identify`.
"""

import numpy as np
import pytest

from gift_theory.lab._explain_output import Z_PASS, _propagate, explain, order_map_classes
from gift_theory.lab import identify

from .test_identify import _first, _net, sim


@pytest.fixture(scope="module")
def small():
    Ws, bs = _net(5, (4, 6, 5, 3))
    x = np.random.default_rng(6).uniform(0, 1, (7, 4))
    return x, list(zip(Ws, bs))


def _deformation(rng):
    return {("gain", 1): 0.1, ("bias", 2): 0.1 * rng.normal(size=5), ("shape", 1): 0.05 * rng.normal(size=7),
            ("shape", 2): 0.05 * rng.normal(size=7), ("alpha", 2): 0.1 * rng.normal(size=5),
            ("beta", 1): 0.1 * rng.normal(size=6), ("alpha", 3): 0.1 * rng.normal(size=3),
            ("shape", 3): 0.02 * rng.normal(size=7), ("weight", 2): 0.1 * rng.normal(size=30)}


@pytest.mark.parametrize("key", [("gain", 1), ("gain", 2), ("gain", 3), ("bias", 1), ("bias", 3), ("alpha", 1),
                                 ("alpha", 2), ("alpha", 3), ("beta", 1), ("beta", 2), ("shape", 1),
                                 ("shape", 2), ("shape", 3), ("weight", 1), ("weight", 2), ("weight", 3)])
def test_each_column_is_the_derivative_of_the_propagated_mean_at_a_deformed_point(small, key):
    """The chain rule carried back draw by draw, at a point where every kind of deformation is
    already in place (the Gauss-Newton steps need the columns there), against central
    differences of the propagated mean on the same draws."""
    x, params = small
    _, _, _, scales = _propagate(x, params, "tanh", 0.05, 3, columns=False)
    base = _deformation(np.random.default_rng(8))
    _, _, cols, _ = _propagate(x, params, "tanh", 0.05, 3, scales, base, columns=True)
    J = cols[key]
    k = J.shape[2]
    h = 1e-6
    for i in range(k):
        def at(sign):
            d = dict(base)
            v = np.array(d.get(key, np.zeros(k)), dtype=np.float64, copy=True).reshape(-1)
            if v.size == 1 and k > 1:
                v = np.zeros(k)
            v[i] += sign * h
            d[key] = float(v[0]) if key[0] == "gain" else v
            return _propagate(x, params, "tanh", 0.05, 3, scales, d)[0]
        fd = (at(1) - at(-1)) / (2 * h)
        assert np.allclose(J[:, :, i], fd, rtol=1e-5, atol=1e-7), (key, i, np.max(np.abs(J[:, :, i] - fd)))


def test_the_shape_polynomials_are_legendres_and_their_slope_its_derivative():
    from gift_theory.lab._explain_output import DEGREE, _legendre, _legendre_slope

    z = np.linspace(-3.0, 3.0, 61)
    assert np.allclose(_legendre(z, 2.5), np.polynomial.legendre.legvander(np.clip(z / 2.5, -1, 1), DEGREE)[:, 1:])
    c = np.random.default_rng(1).normal(size=DEGREE)
    ref = np.polynomial.legendre.legval(z / 2.5, np.polynomial.legendre.legder(np.r_[0.0, c])) / 2.5
    assert np.allclose(_legendre_slope(z, 2.5, c), np.where(np.abs(z) <= 2.5, ref, 0.0))


@pytest.mark.slow
def test_without_taps_a_dead_neuron_is_named_by_the_neuron_that_explains_the_mean():
    meas = sim(12, dead=(2, 3), n=120, r=32, taps=False)
    ident = identify(meas)
    cands = {c.name: c for c in ident.output_candidates}
    assert not cands["programmed"].explains
    right = cands["neuron 2:4's own gain and offset (dead or stuck)"]
    assert right.explains and right.k == 3
    # no other single neuron explains it
    assert not any(c.explains for n, c in cands.items() if n.startswith("neuron") and c is not right)
    m = _first(ident)
    assert m[0]["mechanism"] == "activation_mismatch" and m[0]["layers"] == [2]
    assert "neuron 2:4" in m[0]["evidence"]


@pytest.mark.slow
def test_without_taps_a_gain_on_every_layer_is_a_gain_error_and_a_null_is_left_alone():
    gain = identify(sim(11, gains={1: 0.7, 2: 0.7, 3: 0.7}, n=120, r=32, taps=False))
    cands = {c.name: c for c in gain.output_candidates}
    assert not cands["programmed"].explains and cands["a gain on every layer"].explains
    assert _first(gain)[0]["mechanism"] == "gain_error"
    null = identify(sim(15, n=120, r=32, taps=False))
    prog = next(c for c in null.output_candidates if c.name == "programmed")
    assert prog.explains and prog.z < Z_PASS
    # nothing to reorder on a programmed mean: the mechanism list is the tests' alone
    mechs = [{"mechanism": "weight_error", "layers": [3], "score": 5.0, "evidence": "", "p_value": 1e-6}]
    assert order_map_classes(mechs, null.output_candidates) == mechs


@pytest.mark.slow
def test_without_taps_a_transfer_that_is_not_tanh_leads_as_activation_mismatch():
    meas = sim(21, n=160, r=32, act=np.sin, taps=False)
    ident = identify(meas)
    cands = sorted((c for c in ident.output_candidates if c.explains), key=lambda c: c.bic)
    assert cands and cands[0].mechanism == "activation_mismatch", [(c.name, c.k, c.z) for c in cands[:4]]
    assert _first(ident)[0]["mechanism"] == "activation_mismatch"


@pytest.mark.slow
def test_explain_is_deterministic_and_reports_every_class():
    meas = sim(12, dead=(2, 3), n=120, r=16, taps=False)
    a = explain(meas, 0.05)
    b = explain(meas, 0.05)
    assert [(c.name, c.q) for c in a] == [(c.name, c.q) for c in b]
    assert {c.mechanism for c in a} >= {"none", "gain_error", "bias_offset", "activation_mismatch",
                                        "readout_nonlinearity", "weight_error"}


@pytest.mark.slow
@pytest.mark.parametrize("seed,widths", [(21, (4, 12, 5)), (22, (4, 12, 5)), (23, (6, 10, 8, 4))])
def test_without_taps_a_square_law_detector_is_the_outputs_transfer(seed, widths):
    """y = z_L^2 (an intensity detector): the output's mean is E (z + n)^2, a polynomial of z; the
    output's curve with its constant added after it reproduces it through the model (the
    constant as a shift of z_L before the curve was bent by the curve's large coefficients:
    z = 255080 through the model where the linear fit had z = 2), and readout_nonlinearity
    leads the mechanisms. Seed 22: the level the output's spread gives (0.061 against the
    chip's 0.1) leaves the curve at z = 3.2; fitted again over a few levels it explains."""

    ident = identify(sim(seed, widths=widths, n=160, r=32, s=0.1, taps=False, square_law=True))
    cands = {c.name: c for c in ident.output_candidates}
    assert not cands["programmed"].explains
    assert cands["the output's transfer (a curve shared by its neurons)"].explains
    assert _first(ident)[0]["mechanism"] == "readout_nonlinearity"


def test_a_class_whose_candidates_fail_the_mean_is_refused_when_another_class_reproduces_it():
    """Rule e of the verdict (no taps): a fitted effect whose class, put into the model, leaves
    the output's mean unexplained while another class reproduces it is no explanation; a
    transfer's two classes are one group there (an activation's shape and a readout's curve
    cannot be told apart without taps); noise classes and unchecked classes are not judged."""
    from gift_theory.lab._explain_output import OutputCandidate, mean_refusal

    def c(mech, name, z):
        return OutputCandidate(mech, name, (1,), 4, 100.0, z, 0.5, 100.0 + z)

    cands = [c("none", "programmed", 14.0), c("gain_error", "a gain on every layer", 6.0),
             c("readout_nonlinearity", "each output neuron's gain and offset", 0.5)]
    why = mean_refusal({"gain_error"}, cands)
    assert why and "gain_error does not reproduce" in why and "each output neuron's gain and offset" in why
    assert mean_refusal({"readout_nonlinearity"}, cands) is None  # its own class explains
    assert mean_refusal({"activation_mismatch"}, cands) is None  # one group with the readout
    assert mean_refusal({"noise_law"}, cands) is None  # no mean candidate
    assert mean_refusal({"bias_offset"}, cands) is None  # not checked through the model
    assert mean_refusal({"gain_error"}, cands[:2]) is None  # nothing else explains either


def test_an_explanation_names_the_other_classes_that_reproduce_the_mean_as_well():
    """Without taps several classes can reproduce the output's mean; an explanation by one of
    them says which others do as well (a transfer's two classes are one group)."""
    from gift_theory.lab._explain_output import OutputCandidate, also_explaining

    def c(mech, name, z, k=4):
        return OutputCandidate(mech, name, (1,), k, 100.0, z, 0.5, 100.0 + z + k)

    cands = [c("none", "programmed", 14.0), c("gain_error", "a gain on every layer", 1.8),
             c("readout_nonlinearity", "each output neuron's gain and offset", 0.5, 7),
             c("activation_mismatch", "layer 1's transfer", 0.9, 9), c("weight_error", "W2", 5.0)]
    text = also_explaining({"gain_error"}, cands)
    assert "each output neuron's gain and offset" in text and "layer 1's transfer" in text and "W2" not in text
    assert also_explaining({"readout_nonlinearity"}, cands).count("gain on every layer") == 1
    assert "transfer" not in also_explaining({"readout_nonlinearity"}, cands).split("as well by")[1]
    assert also_explaining({"gain_error"}, cands[:2]) is None
