"""Per-device values fitted as fixed offsets: what they are and how they enter the model.

A model cannot know a device's fixed draws -- the weight errors E of ``weight_error``, the bias
offsets delta of ``bias_offset``, the values of a per-neuron parameter of a plugin effect
(``shape = {"p": "neurons"}``). Each such parameter is a :class:`Kind` (an effect's parameter
with its target and layers); :func:`apply_layer` / :func:`apply_all` put a set of offsets into
the weights, biases and physics of a layer or of the whole net. Fitting them:
:mod:`._offset_fit`; the null that allows for them: :mod:`._offset_null`; the checks that
fitted offsets look like their effect: :mod:`._offset_prior`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._measurement import Measurement
from .._params import Layer
from ..effects import REGISTRY
from ._shots import Model


@dataclasses.dataclass(frozen=True)
class Kind:
    """One family of fitted offsets: of effect ``effect``, added to ``target`` -- ``"W"`` (the
    weights), ``"b"`` (the biases) or the name of a per-neuron parameter of the effect -- on
    ``layers`` (1-based)."""

    effect: str
    target: str
    layers: tuple

    def shape(self, arch, layer: int) -> tuple:
        return (arch.widths[layer], arch.widths[layer - 1]) if self.target == "W" else (arch.widths[layer],)


def _in_scope(cls, layer: int, depth: int) -> bool:
    scope = getattr(cls, "layers", "all")
    if scope == "all":
        return True
    if scope == "hidden":
        return layer < depth
    if scope == "output":
        return layer == depth
    return layer in tuple(scope)


def kinds_of(names, arch) -> tuple:
    """The offset families of the effects ``names`` (built-in offsets and per-neuron parameters)."""
    out = []
    for name in names:
        cls = REGISTRY[name]
        layers = tuple(l for l in range(1, arch.depth + 1) if _in_scope(cls, l, arch.depth))
        if getattr(cls, "offsets_of", None):
            out.append(Kind(name, cls.offsets_of, layers))
        for p, kind in getattr(cls, "shape", {}).items():
            if kind == "neurons":
                out.append(Kind(name, p, layers))
    return tuple(out)


def fitted_as_offsets(name: str) -> bool:
    cls = REGISTRY[name]
    return bool(getattr(cls, "offsets_of", None)) or any(v == "neurons" for v in getattr(cls, "shape", {}).values())


def _neuron_values(physics, kind: Kind, layer: int, d, arch):
    """``physics`` with the per-neuron parameter of ``kind`` at ``layer`` set to its base value + d."""
    eff = physics.get(kind.effect)
    base = getattr(eff, kind.target)
    vals = []
    for l in range(1, arch.depth + 1):
        b_l = base[l - 1] if isinstance(base, (tuple, list)) else base
        v = jnp.broadcast_to(jnp.asarray(b_l, jnp.float32), (arch.widths[l],))
        vals.append(v + d if l == layer else v)
    return physics.replace(**{kind.target: tuple(vals)})


def apply_layer(kinds, ds, W, b, physics, layer: int, arch):
    """Layer ``layer``'s (W, b, physics) with the offsets ``ds`` (one array per kind in scope)."""
    for kind, d in zip(kinds, ds):
        if d is None:
            continue
        if kind.target == "W":
            W = W + d
        elif kind.target == "b":
            b = b + d
        else:
            physics = _neuron_values(physics, kind, layer, d, arch)
    return W, b, physics


def apply_all(kinds, deltas, params, physics, arch):
    """Every layer's weights and the physics with the offsets ``deltas`` ({kind: [array per layer
    in scope]}) -- float64 weights, per-neuron parameters as tuples of per-layer arrays."""
    new = []
    for l, (W, b) in enumerate(params, start=1):
        W, b = np.asarray(W, np.float64), np.asarray(b, np.float64)
        for kind in kinds:
            if l in kind.layers and kind.target in ("W", "b"):
                d = np.asarray(deltas[kind][kind.layers.index(l)], np.float64)
                W, b = (W + d, b) if kind.target == "W" else (W, b + d)
        new.append(Layer(W, b))
    for kind in kinds:
        if kind.target in ("W", "b"):
            continue
        eff = physics.get(kind.effect)
        base = getattr(eff, kind.target)
        vals = []
        for l in range(1, arch.depth + 1):
            b_l = base[l - 1] if isinstance(base, (tuple, list)) else base
            v = np.broadcast_to(np.asarray(b_l, np.float64), (arch.widths[l],)).copy()
            if l in kind.layers:
                v = v + np.asarray(deltas[kind][kind.layers.index(l)], np.float64)
            vals.append(jnp.asarray(v, jnp.float32))
        physics = physics.replace(**{kind.target: tuple(vals)})
    return tuple(new), physics


def unflat_vector(v, shapes):
    """A flat vector (numpy or traced) cut into arrays of ``shapes``, in order."""
    out, i = [], 0
    for sh in shapes:
        k = int(np.prod(sh))
        out.append(v[i:i + k].reshape(sh))
        i += k
    return out


def _split_by_kind(ds, kinds):
    out, i = {}, 0
    for k in kinds:
        out[k] = list(ds[i:i + len(k.layers)])
        i += len(k.layers)
    return out


def _initial_scale(kind: Kind, params, physics) -> float:
    if kind.target == "W":
        return 0.2 * float(np.sqrt(np.mean(np.concatenate([np.ravel(W) ** 2 for W, _ in params]))))
    if kind.target == "b":
        return 0.05 + 0.2 * float(np.sqrt(np.mean(np.concatenate([np.ravel(b) ** 2 for _, b in params]))))
    base = np.asarray(getattr(REGISTRY[kind.effect], "defaults", {}).get(kind.target, 1.0), np.float64)
    return 0.1 * max(float(np.sqrt(np.mean(base ** 2))), 0.1)


def reset(physics, kinds):
    """``physics`` with the per-neuron parameters of ``kinds`` at their defaults (the effect added
    where missing): the point every offset of those kinds is measured from."""
    for k in kinds:
        if k.target in ("W", "b"):
            continue
        default = float(REGISTRY[k.effect].defaults.get(k.target, 0.0))
        physics = (physics.replace(**{k.target: default}) if k.effect in physics
                   else physics.with_effect(k.effect, **{k.target: default}))
    return physics


def base_model(model: Model, meas: Measurement) -> Model:
    """What a model's offsets are measured from: the programmed weights, per-neuron parameters at
    their defaults, everything else of ``model``'s physics."""
    kinds = kinds_of(list(model.offsets), meas.arch)
    return Model(reset(model.physics, kinds))


def kind_columns(kinds, arch, layer):
    """Per kind at ``layer``: the directions moving one column of every neuron's block (W: entry
    j of every row, d_in of them; b or a per-neuron parameter: one), and the kind of each column."""
    dirs, owner = [], []
    for ki, k in enumerate(kinds):
        ncols = arch.widths[layer - 1] if k.target == "W" else 1
        for j in range(ncols):
            v = [np.zeros(kk.shape(arch, layer), np.float32) for kk in kinds]
            if k.target == "W":
                v[ki][:, j] = 1.0
            else:
                v[ki][:] = 1.0
            dirs.append(v)
            owner.append(ki)
    basis = tuple(np.stack([d[i] for d in dirs]) for i in range(len(kinds)))
    return basis, np.array(owner)
