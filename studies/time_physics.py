"""Physics in acquisition time, and activation shapes: issue 48's blind set, in plain numpy.

Written from the text of docs/reference.md (§1-§3, §8) and the issue, not from gift's forward
pass, like :mod:`studies.contract_sim`: the generative process of reference §2 with awgn at
level s, plus one of the physics below. ``python -m studies.blind write DIR --physics time``
writes the files (labels in ``DIR/labels.json``, never in a file gift reads).

Every file has acquisition times t (n, r) in one of three orders, drawn per file:
``random`` (a uniform permutation of the n r shots), ``blocked`` (input by input, the shots of
an input one after another, inputs in their index order -- they are drawn at random) or
``interleaved`` (shot k of every input, in index order, before shot k + 1 of any). t is the
shot's rank over n r - 1. The order matters for what a time effect looks like: a slow drift
is seen across the inputs' means when the acquisition is blocked, within the inputs' shots when
it is interleaved or random.

Physics (xi: standard normal; n_*: the file's additive noise, N(0, s^2))::

``intensity_wander``   c, tau      every layer: z_l = g(t) u_l + b_l + n_wl with g(t) = 1 + c w(t),
                                   w a stationary Ornstein-Uhlenbeck process in t of unit variance
                                   and correlation time tau (a fraction of the campaign), one path
                                   shared by every layer (one laser). time_drift (a slow gain:
                                   gain_fluctuation accepted too); every layer
``weight_drift``       D           layer 1: W_1^eff(t) = W_1 + t D, D fixed per device (iid normal,
                                   rms e rms(W_1)). time_drift; layer 1
``detector_memory``    alpha       every layer output (the value fed forward, what a tap reads) and
                                   the output: out_k = D(v_k) + alpha out_{k-1}, k the shot's rank
                                   in acquisition order, out_{-1} = 0 (a detector whose response
                                   to one shot lingers into the next). memory; every layer;
                                   expressible by the built-in ``memory``
``saturable_absorber`` a0, isat    layer 1's activation: h (1 - a0 / (1 + h^2 / isat)), h = tanh(z)
                                   (a saturable absorber after the modulator: small signals lose
                                   a0, large ones pass). activation_mismatch; layer 1
``softsign_modulator`` (none)      hidden layers' activation z / (1 + |z|) instead of tanh (slope 1 at
                                   0 like tanh, a slower saturation). activation_mismatch; hidden

The draws of one file come from one ``numpy.random.Generator``, named by (seed, physics,
index) in :func:`write_time`.
"""

from __future__ import annotations

import json
import os
import sys
import zlib

import numpy as np
from scipy.signal import lfilter

from .contract_sim import OpenPhysics, loguniform

ORDERS = ("random", "blocked", "interleaved")


def acquisition_times(rng, n: int, r: int, order: str) -> np.ndarray:
    """(n, r) normalised acquisition times of the shots in ``order``."""
    if order == "random":
        rank = np.argsort(rng.permutation(n * r)).reshape(n, r)
    elif order == "blocked":
        rank = np.arange(n * r).reshape(n, r)
    elif order == "interleaved":
        rank = np.arange(n * r).reshape(r, n).T
    else:
        raise ValueError(f"unknown acquisition order {order!r}")
    return rank / max(n * r - 1, 1)


def ou_path(rng, times: np.ndarray, tau: float) -> np.ndarray:
    """A stationary Ornstein-Uhlenbeck path of unit variance at ``times`` (any shape), exact."""
    flat = times.ravel()
    order = np.argsort(flat, kind="stable")
    ts = flat[order]
    rho = np.exp(-np.diff(ts) / tau)
    eta = rng.standard_normal(ts.size)
    w = np.empty(ts.size)
    w[0] = eta[0]
    for k in range(1, ts.size):
        w[k] = rho[k - 1] * w[k - 1] + np.sqrt(1.0 - rho[k - 1] ** 2) * eta[k]
    out = np.empty(ts.size)
    out[order] = w
    return out.reshape(times.shape)


def with_memory(v: np.ndarray, t: np.ndarray, alpha: float) -> np.ndarray:
    """out_k = v_k + alpha out_{k-1} along acquisition order (k: rank of t), per neuron; v (n, r, d)."""
    n, r, d = v.shape
    order = np.argsort(t.ravel(), kind="stable")
    seq = v.reshape(n * r, d)[order]
    filt = lfilter([1.0], [1.0, -alpha], seq, axis=0)
    out = np.empty_like(seq)
    out[order] = filt
    return out.reshape(n, r, d)


def _draw_order(rng):
    return ORDERS[int(rng.integers(len(ORDERS)))]


def _draw_wander(rng, widths, n, r):
    return {"c": loguniform(rng, 0.04, 0.1), "tau": float(rng.uniform(0.1, 0.3)), "order": _draw_order(rng)}


def _draw_weight_drift(rng, widths, n, r):
    return {"e": loguniform(rng, 0.15, 0.35), "order": _draw_order(rng)}


def _draw_memory(rng, widths, n, r):
    return {"alpha": float(rng.uniform(0.08, 0.25)), "order": _draw_order(rng)}


def _draw_absorber(rng, widths, n, r):
    return {"a0": float(rng.uniform(0.15, 0.35)), "isat": float(rng.uniform(0.3, 1.0)), "order": _draw_order(rng)}


def _draw_plain(rng, widths, n, r):
    return {"order": _draw_order(rng)}


TIME_PHYSICS = {p.name: p for p in (
    OpenPhysics("intensity_wander", "time_drift", "all", (), (),
                "every layer: gain 1 + c w(t), w an Ornstein-Uhlenbeck path in acquisition time (correlation "
                "time tau of the campaign) shared by the layers", _draw_wander, accepted=("gain_fluctuation",)),
    OpenPhysics("weight_drift", "time_drift", "first", (), (),
                "layer 1: W_eff(t) = W + t D, D fixed per device", _draw_weight_drift),
    OpenPhysics("detector_memory", "memory", "all", ("memory",), (),
                "every layer output: out_k = D(v_k) + alpha out_{k-1} in acquisition order", _draw_memory),
    OpenPhysics("saturable_absorber", "activation_mismatch", "first", (), (),
                "layer 1's activation h (1 - a0 / (1 + h^2 / isat)), h = tanh(z)", _draw_absorber),
    OpenPhysics("softsign_modulator", "activation_mismatch", "hidden", (), (),
                "hidden layers' activation z / (1 + |z|) instead of tanh", _draw_plain),
)}


def simulate_time(rng, widths, Ws, bs, x, r: int, s: float, name: str | None, params: dict):
    """One campaign: y (n, r, d_L), taps [a_1 .. a_{L-1}], t (n, r); ``name`` one of
    :data:`TIME_PHYSICS` or None (awgn only, order ``params["order"]``)."""
    n = x.shape[0]
    L = len(Ws)
    t = acquisition_times(rng, n, r, params.get("order", "random"))
    gain = 1.0
    if name == "intensity_wander":
        gain = (1.0 + params["c"] * ou_path(rng, t, params["tau"]))[:, :, None]
    D = None
    if name == "weight_drift":
        W = Ws[0]
        D = rng.standard_normal(W.shape) * params["e"] * float(np.sqrt(np.mean(W ** 2)))

    def act(z, layer):
        h = np.tanh(z)
        if name == "saturable_absorber" and layer == 1:
            return h * (1.0 - params["a0"] / (1.0 + h * h / params["isat"]))
        if name == "softsign_modulator":
            return z / (1.0 + np.abs(z))
        return h

    def readout(v):
        return with_memory(v, t, params["alpha"]) if name == "detector_memory" else v

    a = x[:, None, :] + rng.normal(0.0, s, (n, r, widths[0]))
    taps = []
    for l in range(L):
        if D is not None and l == 0:
            u = np.einsum("nrp,nrdp->nrd", a, Ws[0][None, None] + t[:, :, None, None] * D[None, None])
        else:
            u = a @ Ws[l].T
        z = gain * u + bs[l] + rng.normal(0.0, s, u.shape)
        if l < L - 1:
            a = readout(act(z, l + 1) + rng.normal(0.0, s, u.shape))
            taps.append(a)
        else:
            a = readout(z)
    return a, taps, t, D


def write_time(folder: str, files_per_physics: int, seed: int, taps: bool, physics=tuple(TIME_PHYSICS),
               nulls: int | None = None):
    """The time set's files (reference §3 keys, t always) and ``folder/labels.json``; returns the
    file names. Random networks as :func:`studies.blind._draw_setting` draws them; each file's
    draws from the stream (seed, physics, index), so the files with and without taps hold the
    same shots."""
    from .blind import _draw_setting, _jsonable, _open_settings, _save_measurement

    for name in physics:
        if name not in TIME_PHYSICS:
            raise ValueError(f"--only: unknown time physics {name!r}; known: {', '.join(TIME_PHYSICS)}")
    os.makedirs(folder, exist_ok=True)
    labels = {}
    for name, i in _open_settings(physics, files_per_physics, files_per_physics if nulls is None else nulls):
        rng = np.random.default_rng([seed, zlib.crc32(name.encode()), i])
        widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps)
        L = len(Ws)
        spec = TIME_PHYSICS.get(name)
        params = spec.draw(rng, widths, n, r) if spec else {"order": _draw_order(rng)}
        y, tp, t, D = simulate_time(rng, widths, Ws, bs, x, r, s, name if spec else None, params)
        fname = f"{name}_{i}.npz"
        _save_measurement(folder, fname, x, y, t, Ws, bs, tp, taps)
        labels[fname] = {"physics": name, "mechanism": spec.mechanism if spec else None,
                         "classes": spec.classes() if spec else [],
                         "layers": spec.layers(L, params) if spec else [],
                         "expressible_by": list(spec.expressible_by) if spec else [],
                         "contained_in": list(spec.contained_in) if spec else [],
                         "definition": spec.definition if spec else "no effect beyond awgn",
                         "params": {"s": s, **_jsonable(params)}, "arch": widths, "n": n, "r": r, "taps": taps,
                         "seed": seed, "setting": "time"}
        sys.stderr.write(f"wrote {fname}: arch {'-'.join(map(str, widths))}, n={n}, r={r}, s={s:.3g}, {name} "
                         f"{json.dumps(_jsonable(params))}\n")
    with open(os.path.join(folder, "labels.json"), "w") as f:
        json.dump(labels, f, indent=1)
    return sorted(labels)
