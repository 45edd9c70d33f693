"""A chip driver behind the Chip protocol (docs/hardware.md): a stand-in for your instrument.

    gift finetune --dataset teacher --arch 4-8-2 --s0 0.05 --chip docs/examples/my_chip.py:make_chip \
        --method calibrate --budget 30 --K1 500 --out calibrated.npz

Replace ``_device_forward`` by your instrument calls (program the phase shifters from W_l, set the
bias currents from b_l, send the inputs, read the detectors). The stand-in has what real chips
have: insertion loss on layer 1, a detector gain and offset per output, a hidden neuron whose bias
current is off, and noise on every stage; it reads its hidden layer (a tap).
"""

import numpy as np

from gift_theory import GiftInputError, Layer
from gift_theory.chips import Ledger, Measurement


class MyOpticalChip:
    """A device driver behind the Chip protocol."""

    def __init__(self, widths, budget_shots=None, seed=0):
        self.widths = tuple(widths)
        self.ledger = Ledger(budget_shots)
        self._rng = np.random.default_rng(seed)  # stands in for the physics of the device

    def _device_forward(self, params, x, shots):
        # --- replace this block by your instrument calls ---------------------------------
        a = np.repeat(np.asarray(x, np.float64)[:, None, :], shots, axis=1)
        a = a + 0.05 * self._rng.standard_normal(a.shape)                  # input modulator noise
        taps = []
        for l, (W, b) in enumerate(params, start=1):
            W, b = np.array(W, np.float64), np.array(b, np.float64)
            if l == 1:
                W = 0.7 * W                                                # insertion loss, 3 dB
                b[0] += 0.4                                                # a bias current off
            z = a @ W.T + b + 0.05 * self._rng.standard_normal(a.shape[:2] + (W.shape[0],))
            if l < len(params):
                a = np.tanh(z) + 0.05 * self._rng.standard_normal(z.shape)
                taps.append(a)
            else:
                a = np.array([1.3, 0.8]) * z + np.array([0.3, -0.2])     # detectors' gains and offsets
        return a, tuple(taps)
        # --------------------------------------------------------------------------------

    def measure(self, params, x, shots, *, taps=False, key=None):
        x = np.asarray(x, np.float64)
        if x.ndim != 2 or x.shape[1] != self.widths[0]:
            raise GiftInputError(f"chip: inputs have shape {x.shape}, the chip takes (n, {self.widths[0]})")
        self.ledger.charge(x.shape[0] * int(shots))                        # rule 1: charge first
        y, hidden = self._device_forward(params, x, int(shots))
        programmed = tuple(Layer(np.asarray(W), np.asarray(b)) for W, b in params)
        return Measurement(x, y, programmed, taps=hidden if taps else None)


def make_chip():
    """What ``--chip docs/examples/my_chip.py:make_chip`` calls."""
    return MyOpticalChip((4, 8, 2))
