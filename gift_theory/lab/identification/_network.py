"""Every layer of a measurement identified (taps) or its output (no taps), the test of equal
noise levels across the layers, and what the output alone cannot separate."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..._arch import NUMPY_ACTIVATIONS as _ACT
from ..._measurement import Measurement
from .._budget import default_workers, map_in_threads, one_blas_thread
from .._discrete import lattice_row
from .._level import ALPHA
from ._layer import identify_layer
from ._layers import layer_inputs
from ._stats import _chi2, _row

#: noise levels of two layers closer than this in log s^2 (5 %: 2.5 % in s) are one level
LEVEL_TOLERANCE = 0.05


@dataclasses.dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`LayerIdentity` per identified layer.

    taps : whether each layer was identified on its own (taps) or only the output
    levels_row : the test of equal noise levels across layers (taps), or None
    output_candidates : without taps, each candidate mechanism put into the model and its lack
        of fit of the output's mean (:func:`~gift_theory.lab._explain_output.explain`), else ()
    """

    taps: bool
    depth: int
    layers: tuple
    levels_row: dict | None = None
    output_candidates: tuple = ()

    def rows(self) -> list[dict]:
        """Every test with its layer and Holm-adjusted p-value (``p_adj``) over classes x layers
        (fresh dicts: a caller may change them)."""
        return [dict(r_) for r_ in self._rows]

    @functools.cached_property
    def _rows(self) -> tuple:
        out = []
        for li in self.layers:
            for rw in li.rows:
                if rw["class"] != "_omnibus":
                    out.append(dict(rw, layer=li.layer))
        if self.levels_row is not None:
            out.append(dict(self.levels_row))
        ps = np.array([r_["p"] for r_ in out])
        order = np.argsort(ps)
        m = len(ps)
        adj, run = np.empty(m), 0.0
        for rank, i in enumerate(order):
            run = max(run, min(1.0, (m - rank) * ps[i]))
            adj[i] = run
        for r_, a in zip(out, adj):
            r_["p_adj"] = float(a)
        return tuple(out)

    def by_layer(self) -> dict:
        return {li.layer: li for li in self.layers}


def identify(meas: Measurement, s: float | None = None, *, output_candidates: bool = True) -> Identification:
    """Identify every layer of ``meas`` (taps) or its output (no taps) from the shots.

    Parameters
    ----------
    meas : Measurement
    s : the noise level the identification starts from (the smoothing of the activation);
        default: read off the within-input spread of the first measured layer
    output_candidates : without taps, also fit each candidate mechanism to the output's mean
        (``output_candidates``; about half an identification's time): False where only the
        tests' rows are read

    Returns
    -------
    Identification
    """
    with one_blas_thread():  # small dense algebra
        return _identify(meas, s, output_candidates)


def _levels_row(out: list) -> dict | None:
    """The test of equal noise levels across the layers (taps), or None with fewer than two
    layers of one level. A layer whose noise variance changes with its signal (its
    input-dependence test rejects at ALPHA, Bonferroni over every test, so no more often than a
    class is named) has no one level: its mean level rises with its signals, and the layers'
    levels differ though each one's noise at zero signal is the chip's (weighted-sum noise
    s (1 + beta |u|) in the hidden layers was named noise_level first: levels 0.051-0.058 there
    against the output's 0.041, the chip's s); the levels are compared over the others."""
    m_tests = 1 + sum(r_["class"] != "_omnibus" for li in out for r_ in li.rows)
    lv = [li for li in out if not any(r_["class"] == "input_dependent_noise" and r_["p"] * m_tests < ALPHA
                                      for r_ in li.rows)]
    if len(lv) < 2:
        return None
    x = np.array([np.log(li.s ** 2) for li in lv])
    se = np.array([2 * li.s_se / max(li.s, 1e-300) for li in lv])
    w = 1.0 / np.maximum(se ** 2, 1e-300)
    xb = float(np.sum(w * x) / np.sum(w))
    # levels within LEVEL_TOLERANCE of each other (in log s^2) are one level: the layers' unit
    # variances are modelled to about 1 % at 16 shots per input (measured on null files)
    q = float(np.sum(w * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) ** 2))
    p, z = _chi2(q, len(lv) - 1)
    zl = np.sign(x - xb) * np.maximum(np.abs(x - xb) - LEVEL_TOLERANCE, 0.0) * np.sqrt(w)
    bad = [li.layer for li, zz in zip(lv, zl) if abs(zz) > 3.0]
    worst = int(np.argmax(np.abs(zl)))
    levels = _row("noise_level", "levels", p, z, float(lv[worst].s),
                  "noise levels per layer " + ", ".join(f"{li.s:.3g}" for li in lv)
                  + f" (layer {lv[worst].layer} stands out, z = {zl[worst]:.1f})")
    levels["layer"] = lv[worst].layer
    levels["layers"] = bad or [lv[worst].layer]
    if len(lv) < len(out):
        levels["evidence"] += (" (layer(s) " + ", ".join(str(li.layer) for li in out if li not in lv)
                               + " left out: their noise variance changes with the signal)")
    return levels


def _identify(meas: Measurement, s: float | None, output_candidates: bool = True) -> Identification:
    act = meas.activation if meas.activation in _ACT else "tanh"
    if s is None:
        Y0 = np.asarray(meas.layers()[0], np.float64)
        s = float(np.sqrt(np.mean(np.var(Y0, axis=1, ddof=1)) / 2.0)) if meas.r > 1 else 0.05
        # relative to the data, not a fixed floor: a constant layer still gets a level > 0
        s = max(s, 1e-7 * float(np.sqrt(np.mean(Y0 ** 2))), np.finfo(np.float32).tiny)
    kept = {}  # the no-taps propagation's draws, the same at every level of the fixed point below
    lays = layer_inputs(meas, s, kept)
    # each layer reads only its own inputs and shots: the layers in the lab's threads
    out = map_in_threads(lambda lay: identify_layer(lay, act, s, meas.t, meas.arch.depth, meas.has_taps), lays,
                         default_workers(meas))
    if not meas.has_taps and meas.arch.depth > 1:
        # the output's regressor and noise are propagated at the level s: again at the level found,
        # to its fixed point (the regressor's mean moves with s at second order, and at 160 x 48
        # shots a start 5 % off rejected the programmed map on null files)
        for _ in range(6):
            if abs(out[-1].s / s - 1.0) < 1e-3:
                break
            s = out[-1].s
            out = [identify_layer(lay, act, s, meas.t, meas.arch.depth, False) for lay in layer_inputs(meas, s, kept)]
    # a layer on a lattice (a quantizing readout): a finding of its own
    ids, Ys = meas.layer_ids(), meas.layers()
    out = [dataclasses.replace(li, rows=li.rows + tuple(rw for rw in [lattice_row(Ys[ids.index(li.layer)], li.layer)]
                                                        if rw is not None)) for li in out]
    cands = ()
    if output_candidates and not meas.has_taps and meas.arch.depth > 1:
        from .._explain_output import explain
        cands = tuple(explain(meas, out[-1].s))
    levels = _levels_row(out) if meas.has_taps and len(out) > 1 else None
    return Identification(meas.has_taps, meas.arch.depth, tuple(out), levels, cands)


#: what the output alone cannot separate (no taps); docs/identification.md has the full table
CANNOT_SEPARATE_WITHOUT_TAPS = (
    "which layer a deviation of the mean map, the gain or the biases sits in (all fold into the output's)",
    "an activation's shape from a readout's transfer",
    "the noise level of one layer from another's (one level is seen)",
)
