"""The Chip protocol, the shot ledger and the simulated chip's law."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.chips import BudgetExceeded, Chip, Ledger, SimulatedChip, chip_eval

ARCH = gt.Architecture((4, 3, 2))


def _params():
    return gt.init_params(jax.random.PRNGKey(0), ARCH)


def test_ledger_counts_shots_and_rounds_evaluations_up():
    led = Ledger()
    led.charge(10)
    led.charge(5)
    assert (led.shots, led.calls) == (15, 2)
    assert led.evaluations(K1=7, K2=2) == 2  # 15 / 14 rounded up
    led.set_budget_evaluations(1, K1=5, K2=2)
    assert led.remaining() == 10
    with pytest.raises(BudgetExceeded):
        led.charge(11)
    assert led.shots == 15  # a refused call is not charged


def test_budget_refuses_before_measuring():
    chip = SimulatedChip(ARCH, gt.awgn(0.1), budget_shots=12)
    x = np.ones((5, 4), np.float32)
    chip.measure(_params(), x, 2)
    with pytest.raises(BudgetExceeded):
        chip.measure(_params(), x, 1)
    assert chip.ledger.shots == 10


def test_protocol_shapes_taps_and_fresh_noise():
    chip = SimulatedChip(ARCH, gt.Physics.create(s=0.2, drift=0.1))
    assert isinstance(chip, Chip)
    x = np.random.default_rng(0).random((6, 4)).astype(np.float32)
    m1 = chip.measure(_params(), x, 3, taps=True)
    m2 = chip.measure(_params(), x, 3)
    assert m1.y.shape == (6, 3, 2) and [a.shape for a in m1.taps] == [(6, 3, 3)] and m1.t.shape == (6, 3)
    assert 0.0 <= m1.t.min() and m1.t.max() <= 1.0
    assert not np.allclose(m1.y, m2.y)  # two campaigns, independent noise
    assert chip.ledger.shots == 36


def test_a_campaign_s_shots_do_not_depend_on_what_was_measured_before():
    """Same seed, same numbers in any order: the noise is keyed by the chip's key and the campaign
    (weights, inputs, shots, taps, times), with no count of the calls made before it."""
    x = np.random.default_rng(0).random((6, 4)).astype(np.float32)
    first, second = (SimulatedChip(ARCH, gt.Physics.create(s=0.2, drift=0.1), key=jax.random.PRNGKey(3))
                     for _ in range(2))
    a1, b1 = first.measure(_params(), x, 3, taps=True), first.measure(_params(), x[:4], 5)
    b2, a2 = second.measure(_params(), x[:4], 5), second.measure(_params(), x, 3, taps=True)
    np.testing.assert_array_equal(a1.y, a2.y)
    np.testing.assert_array_equal(a1.taps[0], a2.taps[0])
    np.testing.assert_array_equal(b1.y, b2.y)
    other = SimulatedChip(ARCH, gt.Physics.create(s=0.2, drift=0.1), key=jax.random.PRNGKey(4))
    assert not np.allclose(other.measure(_params(), x, 3, taps=True).y, a1.y)  # another chip, other noise


def test_simulated_chip_has_the_models_law():
    """Mean and within-input variance of the outputs match the model's, within standard errors."""
    st = 0.3
    chip = SimulatedChip(ARCH, gt.awgn(st), key=jax.random.PRNGKey(np.random.randint(1 << 30)))
    x = np.random.default_rng(1).random((50, 4)).astype(np.float32)
    y_chip = chip.measure(_params(), x, 400).y
    y_mod = np.asarray(gt.simulate(jax.random.PRNGKey(np.random.randint(1 << 30)), _params(), x, gt.awgn(st), ARCH,
                                   shots=400).y)
    for stat in (lambda y: y.mean(1), lambda y: y.var(1, ddof=1)):
        a, b = stat(y_chip), stat(y_mod)
        d = (a - b).mean(0)  # averaged over inputs: independent units
        se = np.sqrt(a.var(0, ddof=1) / 50 + b.var(0, ddof=1) / 50 + (a - b).var(0, ddof=1) / 50)
        assert np.all(np.abs(d) < 5 * se + 1e-9), (d, se)


def test_chip_eval_is_the_per_input_loss():
    chip = SimulatedChip(ARCH, gt.awgn(0.0))
    x = np.random.default_rng(2).random((8, 4)).astype(np.float32)
    y = np.zeros((8, 2), np.float32)
    l = chip_eval(chip, _params(), x, y, 3)
    want = np.sum(np.asarray(gt.forward(_params(), jnp.asarray(x), {}, gt.awgn(0.0), ARCH).y) ** 2, -1)
    np.testing.assert_allclose(l, want, rtol=1e-5)
    assert chip.ledger.evaluations(8, 3) == 1


def test_bad_input_one_line():
    chip = SimulatedChip(ARCH, gt.awgn(0.1))
    with pytest.raises(gt.GiftInputError, match="inputs have shape"):
        chip.measure(_params(), np.ones((3, 5)), 1)
    with pytest.raises(gt.GiftInputError, match="shots"):
        chip.measure(_params(), np.ones((3, 4)), 0)
