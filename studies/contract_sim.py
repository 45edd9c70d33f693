"""An independent chip simulator: reference §1-§3 in plain numpy, plus physics outside the catalogue.

Written from the text of docs/reference.md (§1 the model, §2 the effects, §3 the
file keys), not from gift's forward pass: ``tests/studies/test_contract_sim.py`` checks
that the two agree in distribution on every built-in effect, and the blind studies
(:mod:`studies.blind`) feed gift files whose physics gift has never seen.

The generative process (reference §2), for layers l = 1..L::

    a_0 = x + n_a0
    u_l = W_l^eff a_{l-1}                   (optical weighted sum)
    z_l = g_l * u_l + b_l^eff + n_wl        (g_l: product of the gains, 1 by default)
    a_l = D(act(z_l) + n_al)   (l < L),   y = a_L = D(z_L)     (D(z_L^2) with square_law)
    D   = saturation, then shot, then quantization (each only when present)

Every layer output fed forward is what a tap measures. The catalogue effects (reference §2
names, ``CATALOGUE``) take their §2 parameters; the open physics (``OPEN_PHYSICS``) are
defined below and each declares its reference §6 mechanism class, the layers it acts on
(where a one-step check -- layer l's model fed the measured output of layer l-1 of the
same shot -- must fail), and ``expressible_by``: the catalogue effects whose model is
exactly this physics (after issue 14's built-ins ``bias_offset`` and ``activation_gain``).

Open physics (n: a fresh standard draw of the file's noise law; xi: standard normal):

``activation_gain``  kappa            hidden layers: act(z) = tanh(kappa z).
                                      activation_mismatch; expressible_by [activation_gain]
``bias_offset``      sigma, delta_l   every layer: b_l^eff = b_l + delta_l, delta_l[i] ~ N(0, sigma^2)
                                      drawn once per device (per neuron, fixed).
                                      bias_offset; expressible_by [bias_offset]
``square_law``       (none)           the output detector measures intensity: y = D(z_L^2), the
                                      field z_L including its noise n_wL; no noise after the
                                      square (nothing else changes). readout_nonlinearity; []
``signal_noise``     beta             hidden layers: n_wl = s (1 + beta |u_l|) n, i.e. the
                                      weighted-sum noise's standard deviation grows with the
                                      optical signal; the output layer keeps s.
                                      input_dependent_noise; []
``dense_crosstalk``  k, C_l           every layer: W_l^eff = W_l + k W_l C_l, C_l a fixed dense
                                      (d_{l-1} x d_{l-1}) coupling drawn once per device:
                                      C[j, m] ~ N(0, 1 / c_m) for |j - m| >= 2 and 0 on the
                                      diagonal and first off-diagonals (c_m: the number of such
                                      j in column m), so weight (i, m) picks up k sum_j W[i, j]
                                      C[j, m], of the size of k rms(W[i]). weight_error; []
``activation_shape`` a2               hidden layers: act(z) = tanh(z) + a2 tanh(z)^2 (an
                                      asymmetric saturation of the modulator).
                                      activation_mismatch; []
``ar1_gain``         c, tau           every layer: g_l *= 1 + c xi(k), one stationary AR(1)
                                      process in acquisition order k = 0 .. n r - 1 (the order
                                      of the file's times t), shared by every neuron of every
                                      layer (one laser feeds the chip): xi(0) ~ N(0, 1),
                                      xi(k) = rho xi(k-1) + sqrt(1 - rho^2) eta_k,
                                      rho = exp(-1 / tau), tau in shots. gain_fluctuation; []

The second set (issue 24, ``NEW_PHYSICS``)::

``sin_modulator``    (none)           hidden layers: act(z) = sin(z) (a Mach-Zehnder modulator's
                                      field transfer, slope 1 at 0 like tanh) instead of tanh.
                                      activation_mismatch; []
``bias_drift``       c                layer 1: b_1^eff = b_1 + c t (t the shot's normalised time),
                                      one c for the layer. time_drift; []
``dead_neuron``      layer, neuron    one neuron of one hidden layer transmits nothing: its
                                      activation is 0 (a_l[i] = D(0 + n_al)). activation_mismatch
                                      (reference §6 names a dead neuron there); layers [layer]; []
``common_noise``     c                every layer: z_l += c xi_l, one xi_l per layer per shot shared
                                      by all its neurons (additive). correlated_noise; []
``detector_gain_offset`` gain, offset every layer output: D first maps v[i] to gain[i] v[i] + offset[i],
                                      gain[i] ~ 1 + N(0, gain_sd^2), offset[i] ~ N(0, offset_sd^2),
                                      fixed per device (each output has its own detector).
                                      readout_nonlinearity; []
``student_t_layer``  nu, layer        one layer's n_w and n_a drawn from Student's t with nu
                                      degrees of freedom scaled to standard deviation s.
                                      noise_law; layers [layer]; []
``last_layer_weight_error`` e, E      the last layer only: W_L^eff = W_L + E, E iid N(0, e^2) fixed
                                      per device. weight_error; layers [L]; [] (contained in the
                                      catalogue's weight_error, which puts offsets in every layer)

The catalogue's ``layer_gain`` (reference §2, 2026-11-25) takes ``{"g": [g_1 .. g_L]}``: g_l
multiplies layer l's gain.

Randomness: one ``numpy.random.Generator`` threads through a whole simulation; an effect
draws from it only when present, so a simulation without the open physics consumes exactly
the draws of the original transcription (the blind study's built-in files are unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

#: the effect names of reference §2
CATALOGUE = ("awgn", "laplace", "uniform", "multiplicative", "common_mode", "drift", "crosstalk", "weight_error",
             "shot", "saturation", "quantization", "layer_gain")

#: the mechanism class (reference §6) of every catalogue effect
CLASS_OF = {"awgn": "noise_level", "laplace": "noise_law", "uniform": "noise_law",
            "shot": "input_dependent_noise", "multiplicative": "input_dependent_noise",
            "common_mode": "gain_fluctuation", "drift": "time_drift",
            "crosstalk": "weight_error", "weight_error": "weight_error",
            "saturation": "readout_nonlinearity", "quantization": "readout_nonlinearity",
            "layer_gain": "gain_error"}

#: the mechanism classes of reference §6 (time_drift, correlated_noise, gain_error: 2026-11-25)
MECHANISMS = ("noise_level", "noise_law", "input_dependent_noise", "gain_fluctuation", "time_drift",
              "correlated_noise", "gain_error", "weight_error", "bias_offset", "activation_mismatch",
              "readout_nonlinearity")


def loguniform(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _signed(rng, lo, hi):
    return float(rng.choice([-1, 1]) * rng.uniform(lo, hi))


@dataclass(frozen=True)
class OpenPhysics:
    """A physical effect outside the catalogue, with what a correct diagnosis should say about it.

    name : the effect's name in this simulator (``simulate_contract``'s ``effects`` key)
    mechanism : its reference §6 class
    scope : "all" | "hidden" | "output" | "first" | "drawn" (one layer, drawn per device as
        ``params["layer"]``): the layers it acts on (``layers(L, params)``, 1-based)
    expressible_by : catalogue effects whose model is exactly this physics
    contained_in : catalogue effects whose fitted model contains this physics as one of its
        values although their model (law, structure) is not this physics: a fitted
        ``weight_error`` (free per-device offsets) can take any fixed linear map; noted so a
        study can tell "wrong" from "over-flexible"
    definition : one line, the formula
    draw : ``(rng, widths, n, r) -> params``: the study's strength (visible but not
        overwhelming at 8-16-8-4, 160 inputs x 48 shots, s = 0.1) and the device's fixed draws
    accepted : further classes a diagnosis may name first (none for any physics here yet)
    """

    name: str
    mechanism: str
    scope: str
    expressible_by: tuple[str, ...]
    contained_in: tuple[str, ...]
    definition: str
    draw: Callable
    accepted: tuple[str, ...] = ()

    def layers(self, L: int, params=None) -> list[int]:
        """The 1-based layers it acts on; scope "drawn": the device's ``params["layer"]``."""
        if self.scope == "drawn":
            if params is None:
                raise ValueError(f"{self.name}: the layer it acts on is drawn per device; pass its params")
            return [int(params["layer"])]
        return {"all": list(range(1, L + 1)), "hidden": list(range(1, L)), "output": [L], "first": [1]}[self.scope]

    def classes(self) -> list[str]:
        """The classes accepted as a diagnosis's first mechanism: the primary one, then ``accepted``."""
        return [self.mechanism] + [c for c in self.accepted if c != self.mechanism]


def bias_offset_device(rng, widths, sigma):
    """delta_l[i] ~ N(0, sigma^2), one per neuron of every layer, fixed for the device."""
    return [rng.normal(0.0, sigma, d) for d in widths[1:]]


def dense_coupling_device(rng, widths):
    """C_l (d_{l-1} x d_{l-1}): N(0, 1 / c_m) beyond the first off-diagonals, zero on and next to the diagonal."""
    out = []
    for d in widths[:-1]:
        j, m = np.indices((d, d))
        far = np.abs(j - m) >= 2
        count = np.maximum(far.sum(axis=0), 1)
        out.append(np.where(far, rng.standard_normal((d, d)) / np.sqrt(count)[None, :], 0.0))
    return out


def _draw_bias_offset(rng, widths, n, r):
    sigma = loguniform(rng, 0.04, 0.12)
    return {"sigma": sigma, "delta": bias_offset_device(rng, widths, sigma)}


def _draw_dense_crosstalk(rng, widths, n, r):
    return {"k": _signed(rng, 0.15, 0.35), "C": dense_coupling_device(rng, widths)}


def _draw_ar1_gain(rng, widths, n, r):
    return {"c": loguniform(rng, 0.12, 0.25), "tau": float(rng.uniform(0.01, 0.05) * n * r)}


def _draw_dead_neuron(rng, widths, n, r):
    layer = int(rng.integers(1, len(widths) - 1))  # a hidden layer (1-based)
    return {"layer": layer, "neuron": int(rng.integers(widths[layer]))}


def _draw_detector(rng, widths, n, r):
    gain_sd, offset_sd = loguniform(rng, 0.05, 0.12), loguniform(rng, 0.03, 0.08)
    return {"gain_sd": gain_sd, "offset_sd": offset_sd,
            "gain": [1.0 + rng.normal(0.0, gain_sd, d) for d in widths[1:]],
            "offset": [rng.normal(0.0, offset_sd, d) for d in widths[1:]]}


def _draw_student_t(rng, widths, n, r):
    return {"nu": float(rng.uniform(3.5, 6.0)), "layer": int(rng.integers(1, len(widths)))}


def _draw_last_weight_error(rng, widths, n, r):
    e = loguniform(rng, 0.05, 0.15)
    return {"e": e, "E": rng.normal(0.0, e, (widths[-1], widths[-2]))}


# strengths: at 8-16-8-4, 160 x 48 shots, s = 0.1 the layer-wise mean shifts (for the
# variance effects the variance ratios) are of the size the built-in study's ranges give
OPEN_PHYSICS = {p.name: p for p in (
    OpenPhysics("activation_gain", "activation_mismatch", "hidden", ("activation_gain",), (),
                "hidden layers: act(z) = tanh(kappa z)",
                lambda rng, widths, n, r: {"kappa": 1.0 + _signed(rng, 0.12, 0.25)}),
    OpenPhysics("bias_offset", "bias_offset", "all", ("bias_offset",), (),
                "every layer: b_eff = b + delta, delta[i] ~ N(0, sigma^2) per neuron, fixed per device",
                _draw_bias_offset),
    OpenPhysics("square_law", "readout_nonlinearity", "output", (), (),
                "the output detector measures intensity: y = z_L^2 (z_L with its noise n_wL)",
                lambda rng, widths, n, r: {}),
    OpenPhysics("signal_noise", "input_dependent_noise", "hidden", (), (),
                "hidden layers: n_w = s (1 + beta |u|) n (weighted-sum noise grows with the signal)",
                lambda rng, widths, n, r: {"beta": loguniform(rng, 2.0, 5.0)}),
    OpenPhysics("dense_crosstalk", "weight_error", "all", (), ("weight_error",),
                "every layer: W_eff = W + k W C, C a fixed dense coupling, zero on and next to the diagonal",
                _draw_dense_crosstalk),
    OpenPhysics("activation_shape", "activation_mismatch", "hidden", (), (),
                "hidden layers: act(z) = tanh(z) + a2 tanh(z)^2 (asymmetric saturation)",
                lambda rng, widths, n, r: {"a2": _signed(rng, 0.05, 0.15)}),
    OpenPhysics("ar1_gain", "gain_fluctuation", "all", (), (),
                "every layer: g *= 1 + c xi(k), xi one AR(1) process (correlation time tau shots) in "
                "acquisition order, shared by all neurons and layers",
                _draw_ar1_gain),
    # the second set (issue 24)
    OpenPhysics("sin_modulator", "activation_mismatch", "hidden", (), (),
                "hidden layers: act(z) = sin(z) (a Mach-Zehnder modulator's field transfer) instead of tanh",
                lambda rng, widths, n, r: {}),
    OpenPhysics("bias_drift", "time_drift", "first", (), (),
                "layer 1: b_eff = b + c t, t the shot's normalised acquisition time (one c for the layer)",
                lambda rng, widths, n, r: {"c": _signed(rng, 0.1, 0.25)}),
    OpenPhysics("dead_neuron", "activation_mismatch", "drawn", (), (),
                "one neuron of a hidden layer transmits nothing: a_l[i] = D(0 + n_a) (its activation noise stays)",
                _draw_dead_neuron),
    OpenPhysics("common_noise", "correlated_noise", "all", (), (),
                "every layer: z_l += c xi_l, one xi_l ~ N(0, 1) per layer per shot shared by all its neurons",
                lambda rng, widths, n, r: {"c": loguniform(rng, 0.08, 0.15)}),
    OpenPhysics("detector_gain_offset", "readout_nonlinearity", "all", (), (),
                "every layer output: D first maps v to gain[i] v + offset[i], gain ~ 1 + N(0, gain_sd^2), "
                "offset ~ N(0, offset_sd^2) per neuron, fixed per device",
                _draw_detector),
    OpenPhysics("student_t_layer", "noise_law", "drawn", (), (),
                "one layer: its n_w and n_a drawn from Student's t with nu degrees of freedom, scaled to "
                "standard deviation s",
                _draw_student_t),
    OpenPhysics("last_layer_weight_error", "weight_error", "output", (), ("weight_error",),
                "the last layer only: W_L^eff = W_L + E, E iid N(0, e^2) fixed per device",
                _draw_last_weight_error),
)}

#: issue 24's second set of physics outside the catalogue (``python -m studies.blind write --physics new``)
NEW_PHYSICS = ("sin_modulator", "bias_drift", "dead_neuron", "common_noise", "detector_gain_offset",
               "student_t_layer", "last_layer_weight_error")


def ar1_path(rng, length, tau):
    """A stationary AR(1) path of unit variance and correlation exp(-1/tau) per step: (length,)."""
    rho = float(np.exp(-1.0 / tau))
    eta = rng.standard_normal(length)
    xi = np.empty(length)
    xi[0] = eta[0]
    c = np.sqrt(1.0 - rho ** 2)
    for k in range(1, length):
        xi[k] = rho * xi[k - 1] + c * eta[k]
    return xi


def simulate_contract(rng, widths, Ws, bs, x, r, s, effects: dict, activation=np.tanh, t=None):
    """reference §2 in plain numpy, plus ``OPEN_PHYSICS``.

    Parameters
    ----------
    rng : numpy Generator (every draw of the simulation comes from it, in a fixed order)
    widths : (d_0, ..., d_L)
    Ws, bs : programmed weights, W_l of shape (d_l, d_{l-1}), b_l of shape (d_l,)
    x : (n, d_0) inputs
    r : shots per input
    s : the additive noise level (0: none)
    effects : {name: {param: value}}: catalogue names with their §2 parameters, open physics
        with their ``draw`` output (device arrays included)
    activation : the nonlinearity sigma
    t : None (the acquisition order is a uniform random permutation of the n r shots, drawn
        here) or (n, r) normalised acquisition times

    Returns
    -------
    y : (n, r, d_L); taps : [a_1 .. a_{L-1}], each (n, r, d_l); t : (n, r)
    """
    n = x.shape[0]
    L = len(Ws)
    law = "laplace" if "laplace" in effects else "uniform" if "uniform" in effects else "gaussian"

    def additive(shape, layer=None):
        if "student_t_layer" in effects and layer == effects["student_t_layer"]["layer"]:
            nu = effects["student_t_layer"]["nu"]
            return s * rng.standard_t(nu, shape) / np.sqrt(nu / (nu - 2.0))
        if law == "laplace":
            return rng.laplace(0.0, s / np.sqrt(2.0), shape)
        if law == "uniform":
            return rng.uniform(-np.sqrt(3.0) * s, np.sqrt(3.0) * s, shape)
        return rng.normal(0.0, s, shape)

    if t is None:
        order = rng.permutation(n * r)  # acquisition order of the (input, shot) pairs
        t = (np.argsort(order).reshape(n, r) / max(n * r - 1, 1)).astype(np.float64)
    t = np.asarray(t, dtype=np.float64)
    Weffs = []
    for l, W in enumerate(Ws):
        We = W.copy()
        if "crosstalk" in effects:
            k = effects["crosstalk"]["k"]
            left = np.zeros_like(W)
            left[:, 1:] = W[:, :-1]
            right = np.zeros_like(W)
            right[:, :-1] = W[:, 1:]
            We = We + k * (left + right)
        if "weight_error" in effects:
            We = We + rng.normal(0.0, effects["weight_error"]["e"], W.shape)  # fixed for the device
        if "dense_crosstalk" in effects:
            We = We + effects["dense_crosstalk"]["k"] * (W @ effects["dense_crosstalk"]["C"][l])
        if "last_layer_weight_error" in effects and l == len(Ws) - 1:
            We = We + effects["last_layer_weight_error"]["E"]
        Weffs.append(We)
    if "ar1_gain" in effects:
        rank = np.argsort(np.argsort(t.ravel(), kind="stable"), kind="stable").reshape(n, r)
        laser = 1.0 + effects["ar1_gain"]["c"] * ar1_path(rng, n * r, effects["ar1_gain"]["tau"])[rank]

    def act(z, layer):
        if "activation_gain" in effects:
            z = effects["activation_gain"]["kappa"] * z
        h = np.sin(z) if "sin_modulator" in effects else activation(z)
        if "activation_shape" in effects:
            h = h + effects["activation_shape"]["a2"] * h ** 2
        if "dead_neuron" in effects and layer == effects["dead_neuron"]["layer"]:
            h = h.copy()
            h[..., effects["dead_neuron"]["neuron"]] = 0.0
        return h

    def readout(v, layer):
        if "detector_gain_offset" in effects:
            det = effects["detector_gain_offset"]
            v = det["gain"][layer - 1] * v + det["offset"][layer - 1]
        if "saturation" in effects:
            vm = effects["saturation"]["v_max"]
            v = vm * np.tanh(v / vm)
        if "shot" in effects:
            v = v + np.sqrt(effects["shot"]["q"] * np.abs(v)) * rng.standard_normal(v.shape)
        if "quantization" in effects:
            bits, vr = effects["quantization"]["bits"], effects["quantization"]["v_range"]
            step = 2 * vr / 2 ** bits
            v = np.clip(np.round(v / step) * step, -vr, vr)
        return v

    a = x[:, None, :] + additive((n, r, widths[0]))
    taps = []
    for l in range(L):
        u = a @ Weffs[l].T
        g = np.ones_like(u)
        if "multiplicative" in effects:
            g = g * (1 + effects["multiplicative"]["m"] * rng.standard_normal(u.shape))
        if "common_mode" in effects:
            g = g * (1 + effects["common_mode"]["c"] * rng.standard_normal(u.shape[:2] + (1,)))
        if "drift" in effects:
            g = g * (1 + effects["drift"]["r"] * t[:, :, None])
        if "layer_gain" in effects:
            g = g * effects["layer_gain"]["g"][l]
        if "ar1_gain" in effects:
            g = g * laser[:, :, None]
        b = bs[l] + effects["bias_offset"]["delta"][l] if "bias_offset" in effects else bs[l]
        if "bias_drift" in effects and l == 0:
            b = b + effects["bias_drift"]["c"] * t[:, :, None]
        noise = additive(u.shape, l + 1)
        if "signal_noise" in effects and l < L - 1:
            noise = noise * (1 + effects["signal_noise"]["beta"] * np.abs(u))
        if "common_noise" in effects:
            noise = noise + effects["common_noise"]["c"] * rng.standard_normal(u.shape[:2] + (1,))
        z = g * u + b + noise
        if l < L - 1:
            a = readout(act(z, l + 1) + additive(u.shape, l + 1), l + 1)
            taps.append(a)
        else:
            a = readout(z ** 2 if "square_law" in effects else z, l + 1)
    return a, taps, t
