"""The cost of a model with fitted offsets: its effective degrees of freedom (the ridge's hat-matrix
trace), which the ranking charges every offset candidate."""

import jax
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.lab import simulate_measurement
from gift_theory.lab._offset_kinds import kinds_of  # private: the kinds an offset effect fits per layer

# private: the cost has no public entry of its own (diagnose charges it inside the ranking), and
# on a large measurement it is summed over chunks of inputs -- a slip in the padding or the rows
# dropped would bias the charge of every offset model there, with no error anywhere
from gift_theory.lab import _offset_null
from gift_theory.lab._shots import Model


@pytest.fixture(scope="module")
def chip():
    arch = gt.Architecture.parse("6-9-7-4")
    params = gt.init_params(jax.random.PRNGKey(3), arch)
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(4), (37, 6)))
    return simulate_measurement(jax.random.PRNGKey(5), params, x, gt.Physics.create(s=0.05), shots=16, taps=True)


@pytest.mark.slow
@pytest.mark.parametrize("effect", ["bias_offset", "weight_error"])
def test_the_offsets_cost_read_in_chunks_of_inputs_equals_the_whole(chip, effect, monkeypatch):
    kinds = kinds_of([effect], chip.arch)
    model = Model(gt.Physics.create(s=0.05), None, {effect: 0.05})
    key = jax.random.PRNGKey(0)
    whole, nominal = _offset_null.effective_dof(key, chip, model, kinds)
    # a budget of a few inputs' tangents: weight_error's layers and bias_offset's first read in
    # several chunks of the 37 inputs, the last one padded
    monkeypatch.setattr(_offset_null, "JVP_CHUNK_BYTES", 20 * 16 * 4 * 9 * 4 * 5)
    spans, size = _offset_null.input_chunks(chip.n, 20 * 16 * 4 * 9 * 4)
    assert len(spans) > 4 and spans[-1][1] - spans[-1][0] < size and spans[-1][1] == chip.n
    chunked, nominal2 = _offset_null.effective_dof(key, chip, model, kinds)
    assert nominal2 == nominal
    assert 0.0 < whole < nominal
    # the tangents are float32, and a program of another batch shape may round its reduction over
    # the draws differently: agreement to well below what a dropped or doubled input moves (1e-3)
    np.testing.assert_allclose(chunked, whole, rtol=1e-8)


def test_an_offset_the_data_pin_down_costs_one_and_one_the_prior_sets_costs_nothing(chip):
    kinds = kinds_of(["bias_offset"], chip.arch)
    key = jax.random.PRNGKey(0)
    dof = [_offset_null.effective_dof(key, chip, Model(gt.Physics.create(s=0.05), None, {"bias_offset": e}), kinds)
           for e in (1e-5, 1e-2, 1.0, 1e3)]
    nominal = dof[0][1]
    assert nominal == 9 + 7 + 4  # one bias per neuron
    costs = [d for d, _ in dof]
    assert costs[0] < 0.01 * nominal  # a prior far below the data's resolution: nearly free of cost
    assert all(a < b for a, b in zip(costs, costs[1:]))  # more freedom, more cost
    assert costs[-1] == pytest.approx(nominal, rel=1e-3)  # every bias identified: one each
