"""A fitted chip as an object: what each layer realises of what is programmed, and the noise.

:class:`ChipModel` is what a calibration learned about one device, in a form that predicts it:

    realised_l(p) = eff_l + gain_l (p_l - p0_l)        entries pinned: their realised value

per layer l read off the measurement (``eff_l`` the realised map of the weights ``p0_l`` the file
programmed, ``gain_l`` each row's gain), the layers not read (no taps: the hidden ones) as
programmed, and the noise as a :class:`~gift_theory.Physics`. :meth:`ChipModel.realise` maps
programmed weights to the weights the chip is predicted to realise; with :meth:`ChipModel.physics`
they are a model of the chip's shots, which ``gift compare --chip-model`` scores against a new
measurement and ``gift simulate --chip-model`` draws new measurements from. Saved as one ``.npz`` of
arrays plus a JSON string (no pickle): :meth:`save`, :func:`load_chip_model`.

Two commands write one: ``gift calibrate`` (the maps read with taps, the noise) and ``gift fit
--save-model`` (the fitted physics and, when an effect was fitted as per-device offsets, those
offsets as the layers' realised maps: ``realised = programmed + offset``).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from .._errors import GiftInputError, require
from .._params import Layer


@dataclasses.dataclass(frozen=True)
class LayerResponse:
    """One layer's realised map as a function of the programmed one (see the module docstring)."""

    layer: int
    eff_W: np.ndarray
    eff_b: np.ndarray
    prog_W: np.ndarray
    prog_b: np.ndarray
    gain_W: np.ndarray
    gain_b: np.ndarray
    se_W: np.ndarray
    se_b: np.ndarray
    pinned_W: np.ndarray
    pinned_b: np.ndarray

    def realise(self, W, b, eff=None):
        eW, eb = (self.eff_W, self.eff_b) if eff is None else eff
        rW = eW + self.gain_W[:, None] * (np.asarray(W, np.float64) - self.prog_W)
        rb = eb + self.gain_b * (np.asarray(b, np.float64) - self.prog_b)
        return np.where(self.pinned_W, eW, rW), np.where(self.pinned_b, eb, rb)


@dataclasses.dataclass(frozen=True)
class ChipModel:
    """A fitted chip (module docstring).

    widths : the network; activation : its name
    responses : one :class:`LayerResponse` per layer read
    effects : ``[{"name": ..., "params": {...}}, ...]`` the noise's effects (awgn first); a
        device's configuration (``seed``) rides with the parameters
    source : the measurement it was fitted to (a path or a label)
    intervals : ``{param: [lo, hi]}``, the fit's 95 % intervals (informative; not used to draw)
    plugins : the effects that come from plugins (loading the model needs them registered)
    """

    widths: tuple
    activation: str
    responses: tuple
    effects: tuple
    source: str = ""
    intervals: dict = dataclasses.field(default_factory=dict, compare=False)
    plugins: tuple = ()

    @classmethod
    def from_model(cls, model, meas, *, source: str = "", intervals=None) -> "ChipModel":
        """The chip model of a fitted lab model (:class:`gift_theory.lab.Model`) of ``meas``: its
        physics, and its weights where they differ from the programmed ones (effects fitted as
        per-device offsets) as layers realising ``programmed + offset``."""
        responses = []
        for l, ((W, b), (pW, pb)) in enumerate(zip(model.weights(meas), meas.params), start=1):
            W, b, pW, pb = (np.asarray(a, np.float64) for a in (W, b, pW, pb))
            # compared at the precision the model runs in: a layer merely cast to float32 is not an offset
            if np.array_equal(W.astype(np.float32), pW.astype(np.float32)) and \
                    np.array_equal(b.astype(np.float32), pb.astype(np.float32)):
                continue
            responses.append(LayerResponse(l, W, b, pW, pb, np.ones(W.shape[0]), np.ones(b.shape[0]),
                                           np.zeros_like(W), np.zeros_like(b), np.zeros(W.shape, bool),
                                           np.zeros(b.shape, bool)))
        effects = tuple(effect_json(e) for e in model.physics.effects)
        return cls(tuple(meas.arch.widths), meas.arch.activation, tuple(responses), effects, source,
                   dict(intervals or {}), model.physics.plugin_names)

    @property
    def physics(self):
        from ..effects import Physics, make_effect
        return Physics.of([make_effect(e["name"], "chip model", **e["params"]) for e in self.effects], "chip model")

    def realise(self, params, *, draw=None):
        """The weights the chip is predicted to realise when ``params`` are programmed.

        ``draw``: a numpy Generator to draw the realised maps from their posterior (independent
        entries, their standard errors) instead of the posterior mean -- the uncertainty of a
        prediction.
        """
        out = [(np.asarray(W, np.float64), np.asarray(b, np.float64)) for W, b in params]
        for r in self.responses:
            eff = None
            if draw is not None:
                eff = (r.eff_W + r.se_W * draw.standard_normal(r.eff_W.shape),
                       r.eff_b + r.se_b * draw.standard_normal(r.eff_b.shape))
            out[r.layer - 1] = r.realise(*out[r.layer - 1], eff=eff)
        return tuple(Layer(W, b) for W, b in out)

    def describe(self) -> str:
        layers = ", ".join(str(r.layer) for r in self.responses)
        return f"chip model of {self.source or 'a measurement'}: layers {layers} read; noise {self.physics.describe()}"

    def save(self, path) -> str:
        from .._io import atomic_write

        arrays = {}
        for r in self.responses:
            for f in dataclasses.fields(r):
                if f.name != "layer":
                    arrays[f"l{r.layer}_{f.name}"] = np.asarray(getattr(r, f.name))
        meta = {"kind": "gift chip model", "version": 1, "widths": list(self.widths), "activation": self.activation,
                "layers": [r.layer for r in self.responses], "effects": list(self.effects), "source": self.source,
                "intervals": dict(self.intervals), "plugins": list(self.plugins)}
        arrays["meta_json"] = np.asarray(json.dumps(meta))
        return atomic_write(path, lambda fh: np.savez(fh, **arrays))


def load_chip_model(path) -> ChipModel:
    """A :class:`ChipModel` from a file :meth:`ChipModel.save` wrote (a bad file: one line, exit 2)."""
    import os

    require(os.path.isfile(path), f"{path}: no such chip model file")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        meta = json.loads(str(arrays.pop("meta_json")))
    except Exception as exc:
        raise GiftInputError(f"{path}: not a gift chip model ({type(exc).__name__})") from None
    require(meta.get("kind") == "gift chip model", f"{path}: not a gift chip model (no 'kind' in its metadata)")
    names = [f.name for f in dataclasses.fields(LayerResponse) if f.name != "layer"]
    responses = []
    for l in meta["layers"]:
        missing = [n for n in names if f"l{l}_{n}" not in arrays]
        require(not missing, f"{path}: layer {l} lacks {missing[0] if missing else ''}")
        responses.append(LayerResponse(int(l), **{n: arrays[f"l{l}_{n}"] for n in names}))
    model = ChipModel(tuple(meta["widths"]), meta["activation"], tuple(responses), tuple(meta["effects"]),
                      meta.get("source", ""), dict(meta.get("intervals", {})), tuple(meta.get("plugins", ())))
    from ..effects import REGISTRY

    missing = [e["name"] for e in model.effects if e["name"] not in REGISTRY]
    require(not missing, f"{path}: effect {missing[0] if missing else ''} is not registered: "
                         f"load the plugin that defines it (--plugin FILE.py)")
    model.physics  # a value outside its effect's bounds is a bad input here, not later
    return model


def effect_json(effect) -> dict:
    """One effect as ``{"name": ..., "params": {...}}``: its parameters (a per-neuron one as a list
    per layer) and its configuration fields (a device ``seed``), what :func:`make_effect` takes."""
    params = effect.param_json()
    params.update({f: getattr(effect, f) for f in effect.static_fields})
    return {"name": effect.name, "params": params}
