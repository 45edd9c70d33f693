"""``gift calibrate MEAS``: corrected weights from one measurement of the programmed ones, for a lab
that has files and no driver (docs/reference.md §7).

1. Each layer's realised map (:func:`~gift_theory.calibration.fit_layers`; taps: every layer,
   else the output); a hidden neuron whose whole realised row is 0 where the programmed one is not
   is dead (pinned at its realised values).
2. The noise: the measurement lab run on the file with the realised maps as its weights (so the
   fixed maps are not read as noise): the effects named (``--add``), or the diagnosis' model over
   the noise-like classes (its best passing model when the awgn model fails, else awgn at its
   fitted level).
3. The target: the file's programmed weights (the network the chip should realise), retrained on
   the data set under the identified noise with the dead neurons pinned (warm start).
4. The corrected weights: programmed + (target - realised) / row gain, projected on what each
   layer's inputs span (the closed loop's step, :mod:`._loop`), for the layers read; the others as
   the target. One file cannot tell whether a bias passes through its row's gain: the output
   layer's is taken to (a detector reads z_L, bias included), a hidden layer's not (a bias current
   added to the weighted sum); a second measurement shows which (``gift compare --chip-model``).
5. The prediction: the :class:`~gift_theory.calibration.ChipModel` of the file realises the
   corrected weights; the accuracy on the test set under its noise (``shots`` per input, argmax
   per shot), its 95 % interval from ``draws`` draws of the realised maps from their posterior
   (each with its own shots), and the same for the programmed weights (``accuracy_before``).

One open-loop round: what reprogramming does to an entry (stuck, a nonlinear map) is not in one
file; a second measurement of the corrected weights tells (``gift compare NEW --chip-model``).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from .._measurement import Measurement
from .._params import Layer, params32
from ._fit import fit_layers
from ._loop import _SLOPES, _row_gain, correction, noise_physics
from ._model import ChipModel, LayerResponse

@dataclasses.dataclass(frozen=True)
class FileCalibration:
    """Result of :func:`calibrate_measurement`.

    params : the corrected weights (tuple of Layer, float64)
    model : the :class:`ChipModel` of the file
    predicted_accuracy, predicted_accuracy_interval : of ``params`` on the chip (test set)
    accuracy_before, accuracy_before_interval : of the programmed weights, by the same model
    identified : per layer read, what it showed; not_identified : what the file cannot show
    """

    params: tuple
    model: ChipModel
    predicted_accuracy: float
    predicted_accuracy_interval: tuple
    accuracy_before: float
    accuracy_before_interval: tuple
    identified: dict
    not_identified: tuple

    def as_json(self) -> dict:
        ph = self.model.physics
        return {"effects": list(ph.names), "params": ph.params_json(),
                "predicted_accuracy": self.predicted_accuracy,
                "predicted_accuracy_interval": list(self.predicted_accuracy_interval),
                "accuracy_before": self.accuracy_before,
                "accuracy_before_interval": list(self.accuracy_before_interval),
                "identified": self.identified, "not_identified": list(self.not_identified)}


def _accuracy(key, params, x, labels, physics, arch, shots):
    from .._model import simulate
    out = simulate(key, params32(params), np.asarray(x, np.float32), physics, arch, shots)
    return float(np.mean(np.argmax(np.asarray(out.y), axis=-1) == np.asarray(labels)[:, None]))


def calibrate_measurement(key, meas: Measurement, ds, *, effects=(), retrain: bool = True, draws: int = 40,
                          shots: int = 32, ridge: float = 0.01, source: str = "") -> FileCalibration:
    """Corrected weights for the chip ``meas`` measured (module docstring).

    Parameters
    ----------
    key : PRNG key (the noise fit, the retraining, the predictions)
    meas : Measurement of the programmed weights
    ds : the data set the network classifies (the retraining's and the prediction's)
    effects : names of effects to fit as the noise (default: the diagnosis' choice)
    retrain : False keeps the programmed weights as the target (pre-compensation only)
    draws, shots : the prediction's posterior draws and shots per test input
    ridge : as in :func:`~gift_theory.calibration.calibrate`

    Returns
    -------
    FileCalibration
    """
    from .._arch import Architecture
    from ..finetune._rivals import RETRAIN
    from ..training import Pinned, train

    arch = Architecture(meas.arch.widths, meas.activation)
    L = arch.depth
    slope = _SLOPES[meas.activation if meas.activation in _SLOPES else "tanh"]
    fits = fit_layers(meas)
    prog = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in meas.params]
    eff = list(prog)
    pinned = [(np.zeros(W.shape, bool), np.zeros(b.shape, bool)) for W, b in prog]
    identified = {}
    for f in fits:
        i = f.layer - 1
        eff[i] = (f.W, f.b)
        if f.layer < L:
            dead = np.all(np.abs(f.W) < 3 * f.W_se, axis=1) & (np.linalg.norm(f.W_prog, axis=1) > 0) & \
                np.any(np.abs(f.W_prog) > 3 * f.W_se, axis=1)
            pinned[i][0][dead], pinned[i][1][dead] = True, True
        g = np.clip(_row_gain(f.W, f.W_prog), 0.4, 2.5)
        identified[str(f.layer)] = {
            "rows_gain_median": float(np.median(g)), "rows_gain_range": [float(g.min()), float(g.max())],
            "weight_deviation_rms": float(np.sqrt(np.mean((f.W - f.W_prog) ** 2))),
            "bias_deviation_rms": float(np.sqrt(np.mean((f.b - f.b_prog) ** 2))),
            "dead_neurons": [int(j) for j in np.where(pinned[i][0].all(axis=1))[0]], "noise_level": f.s}
    realised = dataclasses.replace(meas, params=tuple(Layer(W, b) for W, b in eff))
    k_noise, k_train, k_pred = jax.random.split(key, 3)
    physics, _ = noise_physics(k_noise, realised, effects, s=float(np.median([f.s for f in fits])))
    target = prog
    if retrain:
        start = [(np.where(pW, eW, W), np.where(pb, eb, b)) for (W, b), (eW, eb), (pW, pb) in zip(prog, eff, pinned)]
        mask = tuple(Layer(pW, pb) for pW, pb in pinned)
        values = tuple(Layer(eW.astype(np.float32), eb.astype(np.float32)) for eW, eb in eff)
        out = train(k_train, arch, ds.x_train, ds.y_train, physics, RETRAIN, params=params32(start),
                    pinned=Pinned(mask, values))
        target = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in out]
    corrected = [(W.copy(), b.copy()) for W, b in target]
    responses = []
    for f in fits:
        i = f.layer - 1
        pW, pb = pinned[i]
        gW = np.clip(_row_gain(f.W, f.W_prog), 0.4, 2.5)
        gb = gW if f.layer == L else np.ones_like(f.b)  # a detector reads z_L, bias included
        step, _ = correction(f, target[i], (pW, pb), gW, gb, ridge, slope)
        corrected[i] = (np.where(pW, f.W_prog, f.W_prog + step[:, :-1]), np.where(pb, f.b_prog, f.b_prog + step[:, -1]))
        responses.append(LayerResponse(f.layer, f.W, f.b, f.W_prog, f.b_prog, gW, gb, f.W_se, f.b_se, pW, pb))
    effects_json = tuple({"name": e.name, "params": e.param_json()} for e in physics.effects)
    model = ChipModel(tuple(arch.widths), arch.activation, tuple(responses), effects_json, source)
    corrected = tuple(Layer(W, b) for W, b in corrected)
    preds = {}
    for name, p in (("after", corrected), ("before", tuple(Layer(W, b) for W, b in prog))):
        mean = _accuracy(jax.random.fold_in(k_pred, 0), model.realise(p), ds.x_test, ds.labels_test, physics, arch,
                         shots)
        rng = np.random.default_rng(np.asarray(jax.random.key_data(k_pred)).ravel().tolist())
        sample = [_accuracy(jax.random.fold_in(k_pred, 1 + d), model.realise(p, draw=rng), ds.x_test, ds.labels_test,
                            physics, arch, shots) for d in range(draws)]
        preds[name] = (mean, (float(np.percentile(sample, 2.5)), float(np.percentile(sample, 97.5))))
    not_identified = () if meas.has_taps else (
        "the hidden layers' maps (no taps: only the output map is read; the hidden layers are programmed as the target)",)
    not_identified += ("stuck weights (one file cannot show what does not follow a change of the programming; a "
                       "measurement of the corrected weights can: gift compare NEW --chip-model)",)
    return FileCalibration(corrected, model, preds["after"][0], preds["after"][1], preds["before"][0],
                           preds["before"][1], identified, not_identified)
