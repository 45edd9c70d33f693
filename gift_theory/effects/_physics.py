"""A composition of effects: the physics of one device or one model of it.

:class:`Physics` holds the effects of one device in the canonical order and dispatches the
stages of the generative process (reference §2, §2b) to them::

    W_eff = effective_weights(W, l, L)          weights hooks, in order
    b_eff = bias(b, l, L)                       bias hooks, in order
    g_l   = gain(noise, l, t, shape, L)         product of the gain hooks (None: no gain)
    act_l = activation(z, sigma, l, L)          activation hooks composed around sigma
    D(v)  = readout(v, noise, l, L)             readout hooks, in order

Every dispatcher skips the effects whose ``layers`` scope excludes layer ``l`` of an
``L``-layer network. ``L`` (``depth``) may be omitted while every effect's scope is
``"all"`` or a tuple (the built-in effects but ``activation_gain``); a scope
``"hidden"``/``"output"`` then raises ``ValueError``.
"""

from __future__ import annotations

import dataclasses
from typing import Iterable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .. import _random
from .._errors import GiftInputError
from ._base import (
    _HOOKS,
    REGISTRY,
    STAGES,
    Effect,
    _is_builtin,
    as_per_neuron,
    hook_time,
    is_per_neuron,
    json_value,
    make_effect,
    parse_effect,
)
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

    def params(self) -> dict:
        """All physical parameters as ``{"s": ..., "q": ..., ...}`` (names are unique).

        A per-neuron parameter held as arrays is a tuple with one 1-D array per layer."""
        out: dict = {}
        for e in self.effects:
            out.update(e.param_dict())
        return out

    def params_json(self) -> dict:
        """:meth:`params` as JSON values: numbers, a per-neuron parameter as a list of lists."""
        return {k: json_value(v) for k, v in self.params().items()}

    def replace(self, where: str = "parameters", **values) -> "Physics":
        """A copy with parameters changed by name: ``phys.replace(s=0.2, q=0.01)``.

        A per-neuron parameter takes a scalar or one 1-D array per layer (a tuple or list).
        """
        todo = dict(values)
        new = []
        for e in self.effects:
            mine = {p: todo.pop(p) for p in list(todo) if p in e.params}
            for p, v in mine.items():
                if p in e.shape and (is_per_neuron(v) or getattr(v, "ndim", 0) >= 1):
                    mine[p] = as_per_neuron(v)
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

    def expand(self, arch, dtype=None) -> "Physics":
        """A copy whose per-neuron parameters are per-layer arrays (:meth:`Effect.expand`)."""
        return Physics(tuple(e.expand(arch, dtype) for e in self.effects))

    def without(self, name: str) -> "Physics":
        return Physics(tuple(e for e in self.effects if e.name != name))

    def describe(self) -> str:
        parts = []
        for e in self.effects:
            pd = e.param_dict()
            parts.append(e.name + ("(" + ", ".join(f"{k}={_brief(v)}" for k, v in pd.items()) + ")" if pd else ""))
        return " + ".join(parts) if parts else "noiseless"

    # ---- the stages -------------------------------------------------------------------
    def draws(self, arch) -> dict[str, tuple[int, ...]]:
        """Every standard draw one shot needs: ``{key: event_shape}``."""
        out: dict[str, tuple[int, ...]] = {}
        for e in self.effects:
            if _is_builtin(type(e)):
                out.update(e.draws(arch))
                continue
            try:
                out.update(e.draws(arch))
            except GiftInputError:
                raise
            except Exception as exc:  # a plugin's own failure
                raise GiftInputError(plugin_failure_line(type(e), "draws", exc)) from None
        return out

    def standard(self, key, shape, dtype):
        """Unit-variance draws of the additive noise law."""
        for e in self.effects:
            if e.stage == "law":
                return e.standard(key, shape, dtype)
        return _random.normal(key, shape, dtype)

    def effective_weights(self, W: jax.Array, layer: int, depth: int | None = None, t=None) -> jax.Array:
        """W_eff of layer ``layer`` (1-based) of a ``depth``-layer network: the weights hooks in
        order. ``t``: the shots' acquisition times (batch shape) or None; a hook that takes t
        gets it as (..., 1, 1), and W_eff then has the batch axes in front."""
        for e in self.effects:
            if e.stage == "weights" and e.acts_on(layer, depth):
                W = _call(e, "weights", layer, t, 2, W, layer)
        return W

    def bias(self, b: jax.Array, layer: int, depth: int | None = None, t=None) -> jax.Array:
        """b_eff of layer ``layer``: the bias hooks in order (``b`` itself without any); a hook
        that takes t gets it as (..., 1)."""
        for e in self.effects:
            if e.stage == "bias" and e.acts_on(layer, depth):
                b = _call(e, "bias", layer, t, 1, b, layer)
        return b

    def gain(self, noise, layer, t, shape, depth: int | None = None):
        """g_l: the product of the gain hooks acting on ``layer``; ``None`` when there is none."""
        g = None
        for e in self.effects:
            if e.stage == "gain" and e.acts_on(layer, depth):
                gi = _call(e, "gain", layer, None, 0, noise, layer, t, shape)
                g = gi if g is None else g * gi
        return g

    def activation(self, z: jax.Array, sigma, layer: int, depth: int | None = None, t=None) -> jax.Array:
        """act_l(z) of hidden layer ``layer``, the value before its activation noise.

        The activation hooks acting on ``layer`` are composed in the canonical order: the
        first receives the architecture's ``sigma``, each next one the function the previous
        one defines (``z -> previous.activation(z, sigma, layer)``). Without any: ``sigma(z)``.
        """
        for e in self.effects:
            if e.stage == "activation" and e.acts_on(layer, depth):
                sigma = _Composed(e, sigma, layer, t)
        return sigma(z)

    def readout(self, v, noise, layer, depth: int | None = None, t=None):
        """One pass through the readout chain D of layer ``layer``: the readout hooks in order."""
        for e in self.effects:
            if e.stage == "readout" and e.acts_on(layer, depth):
                v = _call(e, "readout", layer, t, 1, v, noise, layer)
        return v

    def needs_times(self) -> tuple[str, ...]:
        """The names of the effects that need acquisition times (``needs_times``)."""
        return tuple(e.name for e in self.effects if getattr(e, "needs_times", False))

    def check_scope(self, arch, where: str = "effects") -> "Physics":
        """Refuse an effect whose ``layers`` scope names a layer the network ``arch`` does not have,
        or leaves it no layer to act on (:func:`scope_error`); returns ``self``."""
        for e in self.effects:
            err = scope_error(type(e), arch.depth)
            if err:
                raise GiftInputError(f"{where}: {err}")
        return self

    def validate(self, where: str = "effects", arch=None) -> "Physics":
        """Check every effect's parameters (:meth:`Effect.validate`); ``arch`` also checks
        the per-neuron arrays against the network's widths."""
        for e in self.effects:
            e.validate(where, arch)
        return self


def scope_error(cls, depth: int) -> str | None:
    """Why effect class ``cls`` cannot act on a ``depth``-layer network as its ``layers`` scope
    says -- it names a layer beyond ``depth``, or leaves its stage no layer (an activation hook
    acts on hidden layers only) -- or None. A plugin is named by its file."""
    layers = getattr(cls, "layers", "all")
    who = f"effect {cls.name}" + ("" if _is_builtin(cls) else f" ({plugin_file(cls)})")
    if isinstance(layers, (tuple, list)):
        beyond = [int(l) for l in layers if int(l) > depth]
        if beyond:
            return (f"{who}: layers={tuple(layers)} names layer {beyond[0]}, but the network has {depth} "
                    f"layer{'s' if depth > 1 else ''} (1..{depth})")
    acting = [l for l in range(1, depth + 1)
              if (layers == "all" or (layers == "hidden" and l < depth) or (layers == "output" and l == depth)
                  or (isinstance(layers, (tuple, list)) and l in layers))
              and not (cls.stage == "activation" and l == depth)]
    if not acting:
        return (f"{who}: layers={layers!r} leaves its stage {cls.stage!r} no layer of this {depth}-layer network"
                + (" (an activation acts on hidden layers only)" if cls.stage == "activation" else ""))
    return None


class _Composed:
    """``z -> effect.activation(z, sigma, layer[, t])``: one activation hook wrapped around ``sigma``."""

    __slots__ = ("effect", "sigma", "layer", "t")

    def __init__(self, effect, sigma, layer, t=None):
        self.effect, self.sigma, self.layer, self.t = effect, sigma, layer, t

    def __call__(self, z):
        return _call(self.effect, "activation", self.layer, self.t, 1, z, self.sigma, self.layer)


def _shaped_time(t, trailing: int):
    """The times (batch shape) with ``trailing`` unit axes, to broadcast against a hook's value."""
    t = jnp.asarray(t)
    return t.reshape(t.shape + (1,) * trailing)


def _call(effect: Effect, hook: str, layer: int, t, trailing: int, *args):
    """``effect.<hook>(*args)`` on :meth:`Effect.at_layer`, with ``t=`` when the hook takes it
    (0 without times). A plugin's hook that raises is a bad input: a one-line
    :class:`GiftInputError` naming the plugin file, the effect, the hook and the exception
    (a built-in effect's error is the package's own and propagates as it is)."""
    eff = effect.at_layer(layer)
    fn = getattr(eff, hook)
    kwargs = {}
    if hook != "gain":
        mode = hook_time(type(effect), hook)
        if mode is not None and (t is not None or mode == "required"):
            kwargs["t"] = _shaped_time(0.0 if t is None else t, trailing)
    if _is_builtin(type(effect)):
        return fn(*args, **kwargs)
    try:
        out = fn(*args, **kwargs)
    except GiftInputError:
        raise
    except Exception as exc:  # a plugin's own failure while running
        raise GiftInputError(plugin_failure_line(type(effect), hook, exc)) from None
    return checked_result(type(effect), hook, out, _natural_shape(hook, args, kwargs.get("t")), args[0])


def _natural_shape(hook: str, args, t) -> tuple:
    """The shape a hook's result must broadcast to without growing it: its first argument's
    (weights, bias, activation, readout), with the time's batch axes when it took ``t``, or the
    ``shape`` a gain is asked for."""
    if hook == "gain":
        return tuple(args[3])
    shape = tuple(jnp.shape(args[0]))
    return shape if t is None else tuple(jnp.broadcast_shapes(shape, jnp.shape(t)))


def checked_result(cls, hook: str, out, shape: tuple, like):
    """A plugin hook's result, checked (reference §2b: a plugin that breaks the contract is a bad
    input naming its file, effect and hook): a floating array whose shape broadcasts to
    ``shape`` without growing it -- a weights hook keeps W's trailing (d_l, d_{l-1}) exactly --
    cast to the dtype of ``like`` (the stage's input); finite where its values are known (an
    eager run; inside a compiled program the stage's output is checked by the caller)."""
    where = plugin_failure_line(cls, hook, None)
    try:
        arr = jnp.asarray(out)
    except (TypeError, ValueError):
        raise GiftInputError(f"{where}: returned {type(out).__name__}, not an array of numbers") from None
    if not (jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer)):
        raise GiftInputError(f"{where}: returned dtype {arr.dtype}; a hook returns real numbers")
    try:
        grown = tuple(jnp.broadcast_shapes(arr.shape, shape)) != tuple(shape)
    except ValueError:
        grown = True
    if hook == "weights" and tuple(arr.shape[-2:]) != tuple(shape[-2:]):
        grown = True
    if grown:
        want = f"(..., {shape[-2]}, {shape[-1]})" if hook == "weights" else f"{tuple(shape)} or one that broadcasts to it"
        raise GiftInputError(f"{where}: returned shape {tuple(arr.shape)}, expected {want}")
    arr = arr.astype(jnp.result_type(like)) if hasattr(like, "dtype") else arr
    if not isinstance(arr, jax.core.Tracer):
        bad = ~np.isfinite(np.asarray(arr))
        if bad.any():
            i = np.unravel_index(int(np.argmax(bad)), bad.shape)
            raise GiftInputError(f"{where}: returned {float(np.asarray(arr)[i])!r} at index {list(map(int, i))} "
                                 f"(values must be finite)")
    return arr


def plugin_file(cls) -> str:
    """The file a plugin effect class was defined in (its module's file, else the module name)."""
    import sys

    mod = sys.modules.get(getattr(cls, "__module__", ""))
    path = getattr(mod, "__file__", None)
    if path:
        import os

        rel = os.path.relpath(path)
        return rel if not rel.startswith("..") else path
    return getattr(cls, "__module__", "?")


def plugin_failure_line(cls, hook: str, exc: BaseException | None) -> str:
    """``FILE: effect NAME (class C), hook HOOK(...): raised TYPE: message`` (one line); without
    ``exc``, the part before ``: raised`` (what a check of the hook's result names)."""
    sig = _HOOKS.get(cls.stage, (hook, hook))[1] if hook == _HOOKS.get(cls.stage, ("",))[0] else hook
    head = f"{plugin_file(cls)}: effect {cls.name} (class {cls.__name__}), hook {sig}"
    if exc is None:
        return head
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{head}: raised {type(exc).__name__}{': ' + msg if msg else ''}"


def _brief(v) -> str:
    """A parameter value in :meth:`Physics.describe`: the number, or a summary of per-neuron arrays."""
    if is_per_neuron(v):
        vals = [float(x) for row in v for x in jnp.ravel(jnp.asarray(row))]
        if not vals:
            return "per-neuron[]"
        return f"per-neuron[{len(vals)}, mean {sum(vals) / len(vals):.4g}]"
    return f"{float(v):.4g}"


def awgn(s: float) -> Physics:
    """The paper's baseline physics: additive Gaussian noise of level ``s`` only."""
    return Physics((Awgn(s),))
