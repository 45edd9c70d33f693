"""A composition of effects: the physics of one device or one model of it."""

from __future__ import annotations

import dataclasses
from typing import Iterable, Mapping

import jax
import jax.numpy as jnp

from .. import _random
from .._errors import GiftInputError
from ._base import REGISTRY, STAGES, Effect, make_effect, parse_effect
from .awgn import Awgn


def _sort_key(effect: Effect):
    return (STAGES.index(effect.stage), effect.order)


@jax.tree_util.register_pytree_node_class
@dataclasses.dataclass(frozen=True)
class Physics:
    """An ordered, validated tuple of effects. A pytree: the effects' parameters are leaves.

    Build it with :meth:`create` (``Physics.create(awgn=0.1, shot=0.01)``) or
    :meth:`parse` (``Physics.parse(["awgn=0.1", "shot=0.01"])``). At most one effect
    of each name; at most one noise law (``laplace`` or ``uniform``).
    """

    effects: tuple[Effect, ...] = ()

    # pytree protocol: the tuple of effects is itself a pytree of their leaves. The names are
    # the static aux data: JAX's treedefs of two parameterless effects (laplace, uniform)
    # compare equal, so without them a jitted function compiled for one law served the other
    def tree_flatten(self):
        return (self.effects,), self.names

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        object.__setattr__(obj, "effects", tuple(children[0]))
        return obj

    # ---- construction -------------------------------------------------------------
    @classmethod
    def of(cls, effects: Iterable[Effect], where: str = "effects") -> "Physics":
        effects = tuple(effects)
        names = [e.name for e in effects]
        for n in names:
            if names.count(n) > 1:
                raise GiftInputError(f"{where}: effect {n} given twice")
        laws = [n for n in names if REGISTRY[n].stage == "law"]
        if len(laws) > 1:
            raise GiftInputError(f"{where}: noise laws {' and '.join(laws)} exclude each other")
        return cls(tuple(sorted(effects, key=_sort_key)))

    @classmethod
    def create(cls, s: float | None = 0.1, where: str = "effects", **effects) -> "Physics":
        """``Physics.create(s=0.1, shot=0.01, quantization=dict(bits=6, v_range=1))``.

        ``s`` is the awgn level (``None``: no additive noise). A value ``True`` or
        ``{}`` switches on an effect without parameters or with its defaults.
        """
        out = [] if s is None else [make_effect("awgn", where, s=s)]
        for name, value in effects.items():
            if value is None or value is False:
                continue
            if isinstance(value, Mapping):
                out.append(make_effect(name, where, **value))
            elif value is True:
                out.append(make_effect(name, where))
            else:
                if name not in REGISTRY:
                    raise GiftInputError(f"{where}: unknown effect {name!r}; known: {', '.join(REGISTRY)}")
                params = REGISTRY[name].params
                if len(params) != 1:
                    raise GiftInputError(f"{where}: effect {name} takes {', '.join(params) or 'no'} parameters; "
                                         f"give them as a dict")
                out.append(make_effect(name, where, **{params[0]: value}))
        return cls.of(out, where)

    @classmethod
    def parse(cls, specs: Iterable[str], s: float | None = None, where: str = "effects") -> "Physics":
        """From strings such as ``["awgn=0.1", "shot=0.01", "laplace"]``; ``s`` adds awgn first."""
        out = [] if s is None else [make_effect("awgn", where, s=s)]
        for spec in specs:
            e = parse_effect(spec, where)
            if e.name == "awgn" and out and out[0].name == "awgn" and s is not None:
                out[0] = e
            else:
                out.append(e)
        return cls.of(out, where)

    # ---- queries ------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def get(self, name: str) -> Effect | None:
        for e in self.effects:
            if e.name == name:
                return e
        return None

    @property
    def s(self):
        """The additive noise level (0 without ``awgn``)."""
        e = self.get("awgn")
        return 0.0 if e is None else e.s

    @property
    def law(self) -> str:
        """``gaussian``, ``laplace`` or ``uniform``."""
        for e in self.effects:
            if e.stage == "law":
                return e.name
        return "gaussian"

    def params(self) -> dict[str, float]:
        """All physical parameters as ``{"s": ..., "q": ..., ...}`` (names are unique)."""
        out: dict[str, float] = {}
        for e in self.effects:
            out.update(e.param_dict())
        return out

    def params_json(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.params().items()}

    def replace(self, where: str = "parameters", **values) -> "Physics":
        """A copy with parameters changed by name: ``phys.replace(s=0.2, q=0.01)``."""
        todo = dict(values)
        new = []
        for e in self.effects:
            mine = {p: todo.pop(p) for p in list(todo) if p in e.params}
            new.append(dataclasses.replace(e, **mine) if mine else e)
        if todo:
            raise GiftInputError(f"{where}: no effect of {', '.join(self.names) or 'this physics'} "
                                 f"has parameter {sorted(todo)[0]!r}")
        return Physics(tuple(new))

    def with_effect(self, effect: Effect | str, **values) -> "Physics":
        """A copy with one more effect (replacing one of the same name)."""
        if isinstance(effect, str):
            effect = make_effect(effect, **values)
        kept = [e for e in self.effects if e.name != effect.name]
        return Physics.of(kept + [effect])

    def without(self, name: str) -> "Physics":
        return Physics(tuple(e for e in self.effects if e.name != name))

    def describe(self) -> str:
        parts = []
        for e in self.effects:
            pd = e.param_dict()
            parts.append(e.name + ("(" + ", ".join(f"{k}={float(v):.4g}" for k, v in pd.items()) + ")" if pd else ""))
        return " + ".join(parts) if parts else "noiseless"

    # ---- the stages -------------------------------------------------------------------
    def draws(self, arch) -> dict[str, tuple[int, ...]]:
        """Every standard draw one shot needs: ``{key: event_shape}``."""
        out: dict[str, tuple[int, ...]] = {}
        for e in self.effects:
            out.update(e.draws(arch))
        return out

    def standard(self, key, shape, dtype):
        """Unit-variance draws of the additive noise law."""
        for e in self.effects:
            if e.stage == "law":
                return e.standard(key, shape, dtype)
        return _random.normal(key, shape, dtype)

    def effective_weights(self, W: jax.Array, layer: int) -> jax.Array:
        for e in self.effects:
            if e.stage == "weights":
                W = e.weights(W, layer)
        return W

    def gain(self, noise, layer, t, shape):
        g = None
        for e in self.effects:
            if e.stage == "gain":
                gi = e.gain(noise, layer, t, shape)
                g = gi if g is None else g * gi
        return g

    def readout(self, v, noise, layer):
        for e in self.effects:
            if e.stage == "readout":
                v = e.readout(v, noise, layer)
        return v

    def validate(self, where: str = "effects") -> "Physics":
        for e in self.effects:
            e.validate(where)
        return self


def awgn(s: float) -> Physics:
    """The paper's baseline physics: additive Gaussian noise of level ``s`` only."""
    return Physics((Awgn(s),))
