"""Chips with fixed per-device errors, written from the physics in plain numpy, behind the Chip protocol.

Not library code: the devices the calibration study (``python -m studies.calibration``) runs every
fine-tuning method against. Nothing here calls gift's model, effects or lab; the only imports from
gift are the two protocol types a driver hands back (``Ledger``, ``Measurement``), as a user's
driver would (docs/hardware.md).

The network follows the contract's generative process (docs/reference.md §1-§2), every noise
n ~ N(0, s^2) fresh per shot::

    a_0 = x + n_a0
    z_l = Weff_l(W_l) a_{l-1} + beff_l(b_l) + n_wl
    a_l = tanh(z_l) + n_al            (l < L; a dead neuron's a_l is its fixed value + n_al)
    y   = gain * z_L + offset         (the output detectors)

with the device's fixed errors (drawn once per device from ``seed``, whatever is programmed):

``mesh``       each W_l realised by an SVD and two Clements meshes (:mod:`studies.mesh_sim`) whose
               beamsplitters and phase shifters carry fixed errors (``bs_error``, ``phase_error``
               rad): the errors of the first programming as fixed maps around the core
               (:meth:`FaultyChip._mesh`); ``mesh_decomposed``: every W decomposed afresh.
``stuck``      a fraction of the weights of every layer stuck at 0 whatever is programmed.
``detector``   every output neuron read by a detector of its own gain (1 + N(0, sd_g^2)) and
               offset (N(0, sd_o^2)).
``loss``       insertion loss per layer: Weff = g_l W, g_l = 10^(-dB_l / 20), dB_l ~ U(lo, hi).
``bias``       the hidden layers' biases shifted by fixed N(0, sd^2) offsets (b_eff = b + delta).
``crosstalk``  thermal crosstalk between neighbouring heaters, asymmetric and two neighbours
               deep: Weff[i, j] = W[i, j] + k1 W[i, j-1] + k2 W[i, j+1] + k3 (W[i, j-2] + W[i, j+2]).
``dead``       a few hidden neurons dead: their output a fixed value whatever their input.

A chip's ``forward`` (no budget charged) is what the study's referee scores with.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gift_theory.chips import Ledger, Measurement


@dataclasses.dataclass(frozen=True)
class Faults:
    """The strengths of a device's fixed errors (0 / None: off)."""

    mesh: tuple = ()                 # (bs_error, phase_error) in rad
    mesh_decomposed: bool = False    # every W decomposed afresh (the realised error jumps with W)
    stuck: float = 0.0               # share of weights stuck at 0
    detector: tuple = ()             # (sd of the gains, sd of the offsets)
    loss: tuple = ()                 # (dB_lo, dB_hi) per layer
    bias: float = 0.0                # sd of the hidden bias offsets
    crosstalk: tuple = ()            # (k1, k2, k3)
    dead: int = 0                    # dead neurons per hidden layer


#: the study's chips (name -> faults); the strengths put w0's accuracy 5-15 points below the ideal chip's
CHIPS = {
    "mesh": Faults(mesh=(0.05, 0.05)),
    "mesh_decomposed": Faults(mesh=(0.05, 0.05), mesh_decomposed=True),
    "stuck": Faults(stuck=0.15),
    "detector": Faults(detector=(0.4, 0.5)),
    "loss": Faults(loss=(2.0, 6.0)),
    "bias": Faults(bias=0.6),
    "crosstalk": Faults(crosstalk=(0.3, 0.2, 0.1)),
    "dead": Faults(dead=3),
    "mixed": Faults(mesh=(0.02, 0.02), stuck=0.05, detector=(0.2, 0.2), loss=(1.0, 3.0), bias=0.2,
                    crosstalk=(0.1, 0.06, 0.03), dead=1),
}


class FaultyChip:
    """A device with fixed per-device errors behind the Chip protocol.

    Parameters
    ----------
    widths : (d_0, ..., d_L)
    faults : :class:`Faults`
    s : the additive noise level of every stage
    seed : names the device (its fixed errors) and its shots
    taps : whether the device can read its hidden layers
    budget_shots : the ledger's budget
    """

    def __init__(self, widths, faults: Faults, *, s: float = 0.05, seed: int = 0, taps: bool = True,
                 budget_shots=None):
        self.widths = tuple(int(w) for w in widths)
        self.faults = faults
        self.s = float(s)
        self.taps = bool(taps)
        self.ledger = Ledger(budget_shots)
        self.seed = int(seed)
        self._shots = np.random.default_rng([self.seed, 1])
        dev = np.random.default_rng([self.seed, 0])
        L = len(self.widths) - 1
        shapes = [(self.widths[l + 1], self.widths[l]) for l in range(L)]
        f = faults
        self.stuck = [dev.random(sh) < f.stuck for sh in shapes] if f.stuck else None
        self.gain = (1.0 + f.detector[0] * dev.standard_normal(self.widths[-1])) if f.detector else None
        self.offset = (f.detector[1] * dev.standard_normal(self.widths[-1])) if f.detector else None
        self.loss = (10.0 ** (-dev.uniform(*f.loss, size=L) / 20.0)) if f.loss else None
        self.delta = [f.bias * dev.standard_normal(self.widths[l + 1]) for l in range(L - 1)] if f.bias else None
        self.dead = [dev.choice(self.widths[l + 1], size=f.dead, replace=False) for l in range(L - 1)] \
            if f.dead else None
        self.dead_value = [dev.uniform(-0.8, 0.8, size=f.dead) for _ in range(L - 1)] if f.dead else None
        self._mesh_seed = int(dev.integers(2**31))
        self._maps = None
        self._last = None

    # ------------------------------------------------------------------ the device's physics
    def effective(self, params):
        """The realised (Weff_l, beff_l) of the programmed ``params`` (without the output detectors)."""
        import hashlib
        key = hashlib.sha1(b"".join(np.asarray(a, np.float64).tobytes() for W, b in params for a in (W, b))).digest()
        if self._last is not None and self._last[0] == key:  # the same programming: the same realisation
            return [W.copy() for W in self._last[1]], [b.copy() for b in self._last[2]]
        Ws, bs = self._effective(params)
        self._last = (key, Ws, bs)
        return [W.copy() for W in Ws], [b.copy() for b in bs]

    def _effective(self, params):
        f = self.faults
        Ws = [np.asarray(W, np.float64) for W, _ in params]
        bs = [np.asarray(b, np.float64) for _, b in params]
        if f.mesh:
            Ws = self._mesh(Ws)
        if f.crosstalk:
            k1, k2, k3 = f.crosstalk
            out = []
            for W in Ws:
                P = np.pad(W, ((0, 0), (2, 2)))
                out.append(W + k1 * P[:, 1:-3] + k2 * P[:, 3:-1] + k3 * (P[:, :-4] + P[:, 4:]))
            Ws = out
        if self.stuck is not None:
            Ws = [np.where(m, 0.0, W) for W, m in zip(Ws, self.stuck)]
        if self.loss is not None:
            Ws = [g * W for g, W in zip(self.loss, Ws)]
        if self.delta is not None:
            bs = [b + d for b, d in zip(bs, self.delta)] + bs[len(self.delta):]
        return Ws, bs

    def _mesh(self, Ws):
        """Each W realised through meshes with fixed beamsplitter and phase errors.

        ``mesh``: the errors of the meshes that realise the first weights the chip is given, as
        fixed maps on either side, W_eff = Re(T_U W T_V) with T_U = M_U' M_U^H and T_V = M_V^H M_V'
        (M ideal, M' with the errors): exact for those weights, smooth in W (errors in fixed
        optics around a programmable core). ``mesh_decomposed``: every W decomposed afresh and
        realised by the erring meshes; the phases a decomposition picks jump under tiny changes
        of W (an entry of the real orthogonal U crossing 0 flips a phase by pi), so the realised
        error jumps too -- no calibration through the weights can follow it.
        """
        from .mesh_sim import DeviceLayer, _device_errors, mesh_matrix, program_layer, propagate

        bs, ph = self.faults.mesh
        rng = np.random.default_rng(self._mesh_seed)  # the fixed errors belong to the mesh's places, not to W

        def erring(W):
            lay = program_layer(W)
            dev = DeviceLayer(lay, _device_errors(rng, lay.V, bs, ph), _device_errors(rng, lay.U, bs, ph), 0.0, 0.0, 0.0)
            return lay, dev

        if self.faults.mesh_decomposed:
            return [erring(W)[1].matrix() for W in Ws]
        if self._maps is None:
            self._maps = []
            for W in Ws:
                lay, dev = erring(W)
                Ms = []
                for mesh, err in ((lay.U, dev.errU), (lay.V, dev.errV)):
                    th, phs, out = dev._phases(mesh, err)
                    Ms.append((mesh_matrix(mesh), mesh_matrix(mesh, theta=th, phi=phs, out_phase=out, alpha=err.alpha)))
                (MU, MUe), (MV, MVe) = Ms
                self._maps.append((MUe @ MU.conj().T, MV.conj().T @ MVe))
        return [np.real(TU @ W @ TV) for W, (TU, TV) in zip(Ws, self._maps)]

    def forward(self, params, x, shots: int, rng=None):
        """(y (n, shots, d_L), taps [a_1 .. a_{L-1}]) of fresh shots; charges nothing."""
        rng = self._shots if rng is None else rng
        Ws, bs = self.effective(params)
        x = np.asarray(x, np.float64)
        n, s = x.shape[0], self.s
        a = x[:, None, :] + s * rng.standard_normal((n, shots, x.shape[1]))
        taps = []
        for l, (W, b) in enumerate(zip(Ws, bs)):
            z = a @ W.T + b + s * rng.standard_normal((n, shots, W.shape[0]))
            if l < len(Ws) - 1:
                h = np.tanh(z)
                if self.dead is not None:
                    h[..., self.dead[l]] = self.dead_value[l]
                a = h + s * rng.standard_normal(z.shape)
                taps.append(a)
            else:
                a = z if self.gain is None else self.gain * z + self.offset
        return a, taps

    # ------------------------------------------------------------------ the Chip protocol
    def measure(self, params, x, shots, *, taps=False, key=None):
        x = np.asarray(x, np.float64)
        if x.ndim != 2 or x.shape[1] != self.widths[0]:
            raise ValueError(f"chip: inputs have shape {x.shape}, the chip takes (n, {self.widths[0]})")
        shots = int(shots)
        self.ledger.charge(x.shape[0] * shots)
        y, hidden = self.forward(params, x, shots)
        prog = tuple((np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in params)
        from gift_theory import Layer
        return Measurement(x, y, tuple(Layer(W, b) for W, b in prog),
                           tuple(hidden) if (taps and self.taps and hidden) else None)


def referee_accuracy(chip: FaultyChip, params, x, labels, *, shots: int = 32, seed: int = 12345):
    """Accuracy on the chip: argmax of every shot against the label, ``shots`` fresh shots per input.

    Returns (mean, standard error over inputs); nothing is charged to the chip's budget.
    """
    y, _ = chip.forward(params, x, shots, rng=np.random.default_rng([seed, chip.seed]))
    per_input = (np.argmax(y, axis=-1) == np.asarray(labels)[:, None]).mean(axis=1)
    return float(per_input.mean()), float(per_input.std(ddof=1) / np.sqrt(per_input.size))
