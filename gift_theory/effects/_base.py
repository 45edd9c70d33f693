"""The physical-effect protocol and its composition (reference §2, §2b, §6).

A device and a model are both this generative process with extra effects::

    u_l = W_l^eff a_{l-1}                       (optical weighted sum)
    z_l = g_l * u_l + b_l^eff + n_wl            (g_l: gain, 1 by default)
    a_l = D(act_l(z_l) + n_al)   (l < L),   y = a_L = D(z_L)
    D   = readout chain: saturation, then shot, then quantization

An :class:`Effect` is an immutable pytree: its physical parameters are leaves (so they
can be differentiated and fitted), its configuration is static. An effect acts through
one *stage* of :data:`STAGES` -- ``level``, ``law``, ``weights`` (W_eff), ``bias``
(b_eff), ``gain`` (g_l), ``activation`` (act_l, hidden layers) or ``readout`` (a link
of D) -- and only on the layers its ``layers`` scope names. :class:`~.Physics` applies
the effects of a composition in the canonical order (stage, then ``order``), so the
order in which a user lists them never matters.

The catalogue is open (reference §2b): any :class:`Effect` subclass decorated with
:func:`register` is an effect like the built-in ones. :func:`register` checks the class
against the contract and raises :class:`~gift_theory.GiftInputError` with one line
naming the class and the rule it breaks.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import GiftInputError

#: name -> Effect subclass, filled by :func:`register` (built-in effects and plugins).
REGISTRY: dict[str, type["Effect"]] = {}

#: canonical stage order; inside a stage, the class attribute ``order``.
STAGES = ("level", "law", "weights", "bias", "gain", "activation", "readout")

#: the mechanism classes of reference §6, in the table's order.
MECHANISMS = ("noise_level", "noise_law", "input_dependent_noise", "gain_fluctuation", "time_drift",
              "correlated_noise", "gain_error", "weight_error", "bias_offset", "activation_mismatch",
              "readout_nonlinearity", "memory")

#: the hook a stage's effect must define: (method name, signature shown in error messages)
_HOOKS = {
    "weights": ("weights", "weights(W, layer)"),
    "bias": ("bias", "bias(b, layer)"),
    "gain": ("gain", "gain(noise, layer, t, shape)"),
    "activation": ("activation", "activation(z, sigma, layer)"),
    "readout": ("readout", "readout(v, noise, layer)"),
    "law": ("standard", "standard(key, shape, dtype)"),
}

#: the values a ``shape`` entry may take: one value per neuron, or one per layer
NEURONS = "neurons"
LAYERS = "layers"

#: the hooks that may take the shot's acquisition time as a keyword ``t`` (``gain`` gets it
#: positionally, as it always has)
TIME_HOOKS = ("weights", "bias", "activation", "readout", "gain")


def hook_time(cls, hook: str) -> str | None:
    """How the ``hook`` method of ``cls`` takes the acquisition time: ``"required"`` (a
    parameter ``t`` without default), ``"optional"`` (``t`` with a default, or ``**kwargs``)
    or None (it takes none). ``gain`` always takes it (its fixed signature)."""
    import inspect

    fn = getattr(cls, hook, None)
    if not callable(fn) or fn is getattr(Effect, hook, None):
        return None
    if hook == "gain":
        return "optional"
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    par = sig.parameters.get("t")
    if par is not None and par.kind not in (par.VAR_POSITIONAL, par.VAR_KEYWORD):
        return "required" if par.default is par.empty else "optional"
    return None

_BUILTIN_MODULE = __name__.rpartition(".")[0] + "."  # "gift_theory.effects."


def _is_builtin(cls) -> bool:
    return getattr(cls, "__module__", "").startswith(_BUILTIN_MODULE)


def _same_definition(a, b) -> bool:
    """True for one class object, or the same class re-executed (same module and qualified name)."""
    return a is b or (a.__module__ == b.__module__ and a.__qualname__ == b.__qualname__)


def _label(cls) -> str:
    name = cls.__dict__.get("name", getattr(cls, "name", None))
    if isinstance(name, str) and name:
        return f"effect {name} (class {cls.__name__})"
    return f"effect class {cls.__name__}"


def _scope_error(layers) -> str | None:
    """Why ``layers`` is not a valid scope, or None."""
    if isinstance(layers, str):
        if layers in ("all", "hidden", "output"):
            return None
        return f"layers={layers!r} must be 'all', 'hidden', 'output' or a tuple of 1-based layer numbers"
    if isinstance(layers, (tuple, list)) and layers and all(
            isinstance(l, (int, np.integer)) and not isinstance(l, bool) and l >= 1 for l in layers):
        return None
    return f"layers={layers!r} must be 'all', 'hidden', 'output' or a non-empty tuple of 1-based layer numbers"


def _check_class(cls) -> None:
    """The class-level rules of reference §2b that need no dataclass processing."""
    label = _label(cls)
    name = cls.__dict__.get("name", getattr(cls, "name", None))
    if not isinstance(name, str) or not name:
        raise GiftInputError(f"{label}: needs a class attribute `name`, a non-empty string")
    if not name.isidentifier():
        raise GiftInputError(f"{label}: name {name!r} must be an identifier (letters, digits, _)")
    old = REGISTRY.get(name)
    if old is not None and not _same_definition(old, cls):
        if _is_builtin(old):
            where = f"the built-in effect {name}"
        else:
            mod = sys.modules.get(old.__module__)
            where = f"the effect {name} registered by {getattr(mod, '__file__', None) or old.__module__}"
        raise GiftInputError(f"effect {name!r} (class {cls.__name__}) clashes with {where}")
    stage = getattr(cls, "stage", None)
    if stage not in STAGES:
        raise GiftInputError(f"{label}: stage={stage!r} must be one of {', '.join(STAGES)}")
    mechanism = getattr(cls, "mechanism", None)
    if mechanism not in MECHANISMS:
        what = "needs a class attribute `mechanism`," if mechanism is None else f"mechanism={mechanism!r} must be"
        raise GiftInputError(f"{label}: {what} one of the reference §6 classes {', '.join(MECHANISMS)}")
    if stage == "level" and name != "awgn":
        raise GiftInputError(f"{label}: stage 'level' is awgn's (the additive noise level); "
                             f"a noise law takes stage 'law'")
    if stage in _HOOKS:
        hook, sig = _HOOKS[stage]
        mine = getattr(cls, hook, None)
        if not callable(mine) or mine is getattr(Effect, hook, None):
            article = "an" if sig[0] in "aeiou" else "a"
            raise GiftInputError(f"{label}: stage {stage!r} needs {article} {sig} method")
    err = _scope_error(getattr(cls, "layers", "all"))
    if err:
        raise GiftInputError(f"{label}: {err}")
    layers = cls.layers
    if stage == "level" and layers != "all":
        raise GiftInputError(f"{label}: stage 'level' acts on every additive noise site; layers must be 'all'")
    if stage == "activation" and layers == "output":
        raise GiftInputError(f"{label}: stage 'activation' acts on hidden layers only (the last layer has "
                             f"no activation); layers='output' leaves it nothing")
    params = getattr(cls, "params", ())
    if isinstance(params, str) or not isinstance(params, (tuple, list)) or \
            not all(isinstance(p, str) and p.isidentifier() for p in params):
        raise GiftInputError(f"{label}: params={params!r} must be a tuple of field names")
    if len(set(params)) != len(params):
        raise GiftInputError(f"{label}: params={tuple(params)!r} names a parameter twice")
    for attr in ("bounds", "defaults", "shape"):
        table = getattr(cls, attr, {})
        if not isinstance(table, dict):
            raise GiftInputError(f"{label}: {attr} must be a dict keyed by parameter name")
        extra = [k for k in table if k not in params]
        if extra:
            raise GiftInputError(f"{label}: {attr} names {extra[0]!r}, which is not in params {tuple(params)!r}")
    for p, bound in cls.bounds.items():
        try:
            lo, hi = (float(v) for v in bound)
        except (TypeError, ValueError):
            raise GiftInputError(f"{label}: bounds[{p!r}]={bound!r} must be a pair (low, high)") from None
        if not lo <= hi:
            raise GiftInputError(f"{label}: bounds[{p!r}]=({lo:g}, {hi:g}) is empty")
    for p, v in cls.defaults.items():
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise GiftInputError(f"{label}: defaults[{p!r}]={v!r} must be a number") from None
        lo, hi = cls.bounds.get(p, (-math.inf, math.inf))
        if not lo <= v <= hi:
            raise GiftInputError(f"{label}: defaults[{p!r}]={v:g} is outside bounds [{lo:g}, {hi:g}]")
    for p, kind in cls.shape.items():
        if kind not in (NEURONS, LAYERS):
            raise GiftInputError(f"{label}: shape[{p!r}]={kind!r}; a parameter's shape is 'neurons' or 'layers'")
    static = getattr(cls, "static_fields", ())
    if isinstance(static, str) or not isinstance(static, (tuple, list)):
        raise GiftInputError(f"{label}: static_fields={static!r} must be a tuple of field names")
    both = set(static) & set(params)
    if both:
        raise GiftInputError(f"{label}: {sorted(both)[0]!r} is both a parameter and a static field")
    if not isinstance(getattr(cls, "order", 0), (int, float)):
        raise GiftInputError(f"{label}: order must be a number")


def _fill_defaults(cls) -> None:
    """Give a parameter field declared without a default its ``defaults`` value (so ``Cls()``
    works and a field without a default may follow one with a default)."""
    notes = cls.__dict__.get("__annotations__", {})
    for p in cls.params:
        if p in notes and p not in cls.__dict__ and p in cls.defaults:
            setattr(cls, p, float(cls.defaults[p]))


def register(cls):
    """Class decorator: check an :class:`Effect` subclass against the contract and list it.

    The class becomes a frozen dataclass registered as a JAX pytree (its ``params`` are the
    leaves, its ``static_fields`` the static configuration) and is added to
    :data:`REGISTRY` under its ``name``, after which its name is used like any built-in
    effect's (``Physics.create(act_gain=1.2)``, ``parse_effect("act_gain=1.2")``).

    Parameters
    ----------
    cls : type
        A subclass of :class:`Effect`.

    Returns
    -------
    type
        The same class, now a frozen dataclass pytree.

    Raises
    ------
    GiftInputError
        One line naming the class and the rule it breaks: ``name`` missing or not a string,
        or taken by a different class (re-registering the same class is harmless);
        ``stage`` not in :data:`STAGES`; ``mechanism`` missing or not in :data:`MECHANISMS`;
        the stage's hook not defined (``weights``, ``bias``, ``gain``, ``activation``,
        ``readout``; a ``law`` defines ``standard(key, shape, dtype)``; ``level`` is awgn's);
        ``params`` not dataclass fields or a field that is neither a parameter nor static;
        ``bounds``/``defaults``/``shape`` keys not in ``params``; ``layers`` malformed;
        ``shape`` values other than ``"neurons"``.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise GiftInputError(f"register: {cls!r} is not a subclass of gift_theory.effects.Effect")
    name = cls.__dict__.get("name", getattr(cls, "name", None))
    if isinstance(name, str) and REGISTRY.get(name) is cls:
        return cls  # the identical class again: nothing to do
    _check_class(cls)
    label = _label(cls)
    if isinstance(cls.layers, list):
        cls.layers = tuple(cls.layers)
    cls.params = tuple(cls.params)
    cls.static_fields = tuple(cls.static_fields)
    # a hook that takes the time t without a default cannot run on a file without times
    if "needs_times" not in cls.__dict__ and any(hook_time(cls, h) == "required" for h in TIME_HOOKS):
        cls.needs_times = True
    _fill_defaults(cls)
    try:
        cls = dataclasses.dataclass(frozen=True)(cls)
    except (TypeError, ValueError) as exc:
        raise GiftInputError(f"{label}: not a valid dataclass: {exc}") from None
    fields = [f.name for f in dataclasses.fields(cls)]
    for p in cls.params:
        if p not in fields:
            raise GiftInputError(f"{label}: parameter {p!r} in params is not a dataclass field "
                                 f"(declare it as `{p}: float = ...`)")
    for f in cls.static_fields:
        if f not in fields:
            raise GiftInputError(f"{label}: static field {f!r} is not a dataclass field")
    for f in fields:
        if f not in cls.params and f not in cls.static_fields:
            raise GiftInputError(f"{label}: field {f!r} is neither in params nor in static_fields")
    meta = [f for f in fields if f in cls.static_fields]
    data = [f for f in fields if f not in cls.static_fields]
    jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)
    REGISTRY[cls.name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a plugin effect from :data:`REGISTRY` (tests; a built-in effect stays)."""
    cls = REGISTRY.get(name)
    if cls is not None and not _is_builtin(cls):
        del REGISTRY[name]


def is_per_neuron(value) -> bool:
    """True for a per-neuron value: a sequence with one 1-D array per layer."""
    return isinstance(value, (tuple, list))


def as_per_neuron(value) -> tuple:
    """A per-neuron value (tuple/list/2-D array of per-layer rows) as a tuple of 1-D arrays."""
    rows = []
    for row in value:
        if isinstance(row, jax.Array) or hasattr(row, "aval"):
            rows.append(row)
        else:
            rows.append(jnp.asarray(np.asarray(row, dtype=float), dtype=jnp.result_type(float)))
    return tuple(rows)


def json_value(value):
    """A parameter value as JSON: a number, or a list of lists (one per layer) for a per-neuron one."""
    if is_per_neuron(value):
        return [[float(v) for v in np.asarray(row).reshape(-1)] for row in value]
    return float(value)


class Effect:
    """Base class of a physical effect. Subclasses set the class attributes and define the
    hook of their stage; :func:`register` checks them and makes the class a frozen
    dataclass pytree.

    Class attributes
    ----------------
    name : str
        The effect's name (reference §2 for built-in ones), spelled exactly so.
    params : tuple of str
        The names of its physical parameters: dataclass fields, pytree leaves (fitted,
        differentiated).
    bounds : dict
        Per parameter, ``(low, high)``: the closed interval a value (every element of a
        per-neuron one) must lie in; fitting searches inside it.
    defaults : dict
        A typical starting value per parameter (fitting starts there; a field declared
        without a default takes it).
    stage : str
        One of :data:`STAGES`.
    mechanism : str
        One of :data:`MECHANISMS` (reference §6).
    layers : str or tuple of int
        Where every hook of the effect acts: ``"all"`` (default), ``"hidden"`` (layers
        1..L-1), ``"output"`` (layer L) or a tuple of 1-based layer numbers. An activation
        effect never acts on layer L (it has no activation).
    shape : dict
        ``{param: "neurons"}`` for per-neuron parameters (default ``{}``). Such a parameter
        holds a scalar (every neuron of every layer in scope) or a tuple with one 1-D array
        per layer 1..L; the arrays of layers outside the scope are ignored (:meth:`expand`
        makes them zero-length). Read it with :meth:`value`. ``{param: "layers"}``: one value
        per layer (a (1,)-array per layer, e.g. ``layer_gain``'s g), fixed per device.
    order : int
        Position inside the stage.
    static_fields : tuple of str
        Dataclass fields that are configuration, not parameters (e.g. a device ``seed``).
    description : str
        One line: what the chip does.

    Hooks (identity by default; ``layer`` is 1-based; called only for layers in scope)
    -----------------------------------------------------------------------------------
    ``weights(W, layer)`` -> W_eff; ``bias(b, layer)`` -> b_eff; ``gain(noise, layer, t,
    shape)`` -> g_l; ``activation(z, sigma, layer)`` -> the value before the activation
    noise; ``readout(v, noise, layer)`` -> one link of D; a ``law`` effect defines
    ``standard(key, shape, dtype)`` (unit-variance draws); ``draws(arch)`` lists the
    standard-normal draws an effect needs per shot.

    Any of ``weights``, ``bias``, ``activation``, ``readout`` may also take a keyword ``t``:
    the shot's normalised acquisition time (reference §3), shaped to broadcast against the
    hook's first argument ((..., 1, 1) for W, (..., 1) for the others, ``...`` the shots'
    batch axes); ``gain`` receives t positionally, of the batch shape. A hook whose ``t`` has
    no default makes the effect ``needs_times``; without times the forward pass gives it
    ``t = 0`` and the commands refuse such an effect on a file without ``t``. A hook runs
    on :meth:`at_layer`: ``self.p`` of a per-neuron ``p`` is the layer's (d_l,) values.
    A noise ``law`` restricted by ``layers`` draws the sites ``w_l``, ``a_l`` of its layers
    from its law and the others Gaussian (the input site ``a0`` follows it only under
    ``"all"``).
    """

    name: ClassVar[str]
    params: ClassVar[tuple[str, ...]] = ()
    bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    defaults: ClassVar[dict[str, float]] = {}
    stage: ClassVar[str]
    mechanism: ClassVar[str]
    layers: ClassVar[Any] = "all"
    shape: ClassVar[dict[str, str]] = {}
    order: ClassVar[int] = 0
    static_fields: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""

    # ---- hooks (identity by default) -------------------------------------------
    def draws(self, arch) -> dict[str, tuple[int, ...]]:
        """Standard-normal draws this effect needs per shot: ``{key: event_shape}``."""
        return {}

    def weights(self, W: jax.Array, layer: int) -> jax.Array:
        """``weights`` stage: return W_eff of layer ``layer`` (1-based)."""
        return W

    def bias(self, b: jax.Array, layer: int) -> jax.Array:
        """``bias`` stage: return b_eff of layer ``layer`` (1-based)."""
        return b

    def gain(self, noise: dict, layer: int, t, shape) -> jax.Array | float:
        """``gain`` stage: the factor g_l (broadcastable to ``shape``)."""
        return 1.0

    def activation(self, z: jax.Array, sigma, layer: int) -> jax.Array:
        """``activation`` stage: the value of hidden layer ``layer`` before its activation
        noise, given the pre-activation ``z`` and the activation ``sigma`` (a function; the
        architecture's, or the one the effects before this one made)."""
        return sigma(z)

    def readout(self, v: jax.Array, noise: dict, layer: int) -> jax.Array:
        """``readout`` stage: one link of the chain D."""
        return v

    # ---- scope and parameters ---------------------------------------------------------
    def acts_on(self, layer: int, depth: int | None = None) -> bool:
        """Whether the effect's hooks act on layer ``layer`` (1-based) of a ``depth``-layer net.

        ``depth`` may be omitted for the scopes ``"all"`` and a tuple of layers.
        """
        layers = self.layers
        if layers == "all":
            return True
        if isinstance(layers, (tuple, list)):
            return int(layer) in layers
        if depth is None:
            raise ValueError(f"effect {self.name}: its scope layers={layers!r} needs the network depth")
        return int(layer) < depth if layers == "hidden" else int(layer) == depth

    def value(self, param: str, layer: int):
        """Parameter ``param`` on layer ``layer`` (1-based): what a hook computes with.

        A scalar parameter is returned as it is. A per-neuron parameter (``shape = {param:
        "neurons"}``) is held as a scalar (every neuron the same, e.g. before a fit) or as one
        1-D array per layer; this returns that layer's array, shape (d_l,), which broadcasts
        against the hook's (..., d_l) values -- or the scalar. Public API (reference §2b)::

            @register
            class Transmission(Effect):
                alive: float = 1.0
                name = "transmission"
                params = ("alive",)
                shape = {"alive": "neurons"}      # one value per neuron, fixed per device
                bounds = {"alive": (0.0, 2.0)}
                defaults = {"alive": 1.0}
                stage = "activation"
                layers = "hidden"
                mechanism = "activation_mismatch"

                def activation(self, z, sigma, layer):
                    return self.value("alive", layer) * sigma(z)

        Inside a hook, ``self.alive`` is already that layer's value (the hook runs on
        :meth:`at_layer`), so ``self.alive * sigma(z)`` means the same.

        Parameters
        ----------
        param : str
            One of ``params``.
        layer : int
            1-based layer number.

        Returns
        -------
        float or array of shape (d_l,)
        """
        if param not in self.params:
            raise GiftInputError(f"effect {self.name}: value({param!r}, {layer}): no parameter {param!r}; "
                                 f"it has {', '.join(self.params) or 'none'}")
        v = getattr(self, param)
        if param in self.shape and is_per_neuron(v):
            return v[int(layer) - 1]
        return v

    def at_layer(self, layer: int) -> "Effect":
        """A copy whose per-neuron parameters are layer ``layer``'s values (:meth:`value`): the
        effect a hook of that layer runs on, so ``self.p`` in a hook is the layer's (d_l,) array."""
        new = {p: self.value(p, layer) for p in self.shape if is_per_neuron(getattr(self, p))}
        return dataclasses.replace(self, **new) if new else self

    def _width(self, param: str, arch, layer: int) -> int:
        """Values of a per-neuron (d_l) or per-layer (1) parameter on layer ``layer``."""
        return 1 if self.shape.get(param) == LAYERS else arch.widths[layer]

    def expand(self, arch, dtype=None) -> "Effect":
        """A copy whose per-neuron parameters are arrays: one per layer, of width d_l on the
        layers in scope (filled with the current scalar value) and of length 0 elsewhere.
        Arrays already there are kept. The form a fit of per-neuron values starts from."""
        new = {}
        for p in self.shape:
            v = getattr(self, p)
            if is_per_neuron(v):
                continue
            dt = jnp.result_type(float) if dtype is None else dtype
            new[p] = tuple(jnp.full((self._width(p, arch, l) if self.acts_on(l, arch.depth) else 0,), v, dt)
                           for l in range(1, arch.depth + 1))
        return dataclasses.replace(self, **new) if new else self

    def param_dict(self) -> dict[str, Any]:
        """``{param: value}``; a per-neuron value is a tuple of per-layer arrays."""
        return {p: getattr(self, p) for p in self.params}

    def param_json(self) -> dict[str, Any]:
        """:meth:`param_dict` as JSON values (a per-neuron one as a list of lists)."""
        return {p: json_value(v) for p, v in self.param_dict().items()}

    def validate(self, where: str = "effect", arch=None) -> "Effect":
        """Check the parameter values against ``bounds`` (every element of a per-neuron one)
        and, given ``arch``, the per-neuron arrays' count and lengths.

        Raises :class:`GiftInputError` naming the first bad value.
        """
        for p in self.params:
            v = getattr(self, p)
            if is_per_neuron(v):
                if p not in self.shape:
                    raise GiftInputError(f"{where}: {self.name} parameter {p} must be a number")
                self._validate_rows(p, v, where, arch)
                continue
            try:
                v = float(v)
            except (TypeError, ValueError):
                per = " or one array per layer" if p in self.shape else ""
                raise GiftInputError(f"{where}: {self.name} parameter {p} must be a number{per}") from None
            lo, hi = self.bounds.get(p, (-float("inf"), float("inf")))
            if not (lo <= v <= hi) or v != v:
                raise GiftInputError(f"{where}: {self.name} parameter {p}={v:g} is outside [{lo:g}, {hi:g}]")
        return self

    def _validate_rows(self, p, rows, where, arch):
        lo, hi = self.bounds.get(p, (-float("inf"), float("inf")))
        if arch is not None and len(rows) != arch.depth:
            raise GiftInputError(f"{where}: {self.name} parameter {p} has {len(rows)} per-layer arrays; "
                                 f"the network has {arch.depth} layers")
        for l, row in enumerate(rows, start=1):
            try:
                a = np.asarray(row, dtype=float)
            except (TypeError, ValueError):
                raise GiftInputError(f"{where}: {self.name} parameter {p} layer {l}: not an array of numbers") from None
            if a.ndim != 1:
                raise GiftInputError(f"{where}: {self.name} parameter {p} layer {l}: must be 1-D (one value per "
                                     f"neuron), got shape {a.shape}")
            if arch is not None and self.acts_on(l, arch.depth) and a.shape[0] != self._width(p, arch, l):
                raise GiftInputError(f"{where}: {self.name} parameter {p} layer {l}: {a.shape[0]} values for "
                                     f"{self._width(p, arch, l)} " + ("value (one per layer)" if self.shape[p] == LAYERS
                                                                      else "neurons"))
            bad = ~((a >= lo) & (a <= hi))
            if bad.any():
                i = int(np.argmax(bad))
                raise GiftInputError(f"{where}: {self.name} parameter {p} layer {l} neuron {i + 1}: {a[i]:g} is "
                                     f"outside [{lo:g}, {hi:g}]")


    # ---- what the measurement lab knows about it (fitting, ranking, signatures) -----
    #: fitted as per-device fixed offsets of the programmed weights ("W") or biases ("b"),
    #: with its (single) parameter the prior scale of those offsets (weight_error,
    #: bias_offset); None: its parameters are fitted by moment matching
    offsets_of: ClassVar[str | None] = None
    #: silent without acquisition times (a diagnosis tries it only on files that have them);
    #: set by :func:`register` when a hook takes ``t`` without a default
    needs_times: ClassVar[bool] = False

    @classmethod
    def search(cls, param: str, layers) -> np.ndarray:
        """Values of ``param`` a fit scans before refining them.

        Default, from the parameter's ``bounds`` and ``defaults``: a positive parameter (lower
        bound >= 0) 16 log-spaced values over [default / 1000, 30 default], a signed one 25
        evenly spaced values over its bounds when they are finite, else over +-15 |default|;
        always inside the bounds. ``layers``: the measured layer outputs (each (n, r, d_l)),
        for an effect whose scale is the data's.
        """
        lo, hi = cls.bounds.get(param, (-np.inf, np.inf))
        d = abs(float(cls.defaults.get(param, 1.0))) or 1.0
        if lo >= 0:
            vals = np.geomspace(max(d * 1e-3, lo, 1e-12), d * 30.0, 16)
        elif np.isfinite(lo) and np.isfinite(hi):
            vals = np.linspace(lo, hi, 25)
        else:
            vals = np.linspace(-15.0 * d, 15.0 * d, 25)
        vals = vals[(vals >= lo) & (vals <= hi)]
        return vals if vals.size else np.array([float(cls.defaults.get(param, max(lo, min(hi, 1.0))))])

    @classmethod
    def from_data(cls, layers) -> dict | None:
        """Parameter values read off the measured layers (each (n, r, d_l)) and held fixed by a
        fit, or None (default: nothing is read off the data)."""
        return None

    @classmethod
    def signature(cls, res) -> dict | None:
        """This effect's signature in the residuals of a model without it, or None.

        ``res`` (:class:`gift_theory.lab.Residuals`) holds per measured layer the measured and
        the model's per-cell means, variances and shots (the model's, on a large file, made
        again a block of inputs at a time on each reading: a statistic of each input's model
        shots reads them once with ``res.per_input_of_model_halves``). Returns ``{"statistic": str,
        "value": float, "z": float}`` with z ~ N(0, 1) under the model (a score test in the
        direction the effect would move the data); large positive z points at the effect.
        """
        return None

def _coerce(cls, p, value, where):
    """A user's value of parameter ``p`` of ``cls``: a float, or a tuple of arrays if per neuron."""
    if p in cls.shape and (is_per_neuron(value) or np.ndim(value) >= 1):
        try:
            return as_per_neuron(value)
        except (TypeError, ValueError):
            raise GiftInputError(f"{where}: effect {cls.name} parameter {p}: not one array of numbers "
                                 f"per layer") from None
    try:
        return float(value)
    except (TypeError, ValueError):
        per = " or one array per layer" if p in cls.shape else ""
        raise GiftInputError(f"{where}: effect {cls.name} parameter {p} must be a number{per}") from None


def make_effect(name: str, where: str = "effect", **values) -> Effect:
    """Build the effect ``name`` with parameter ``values`` (missing ones take defaults).

    A per-neuron parameter (``shape``) takes a number or one 1-D array per layer.
    """
    if name not in REGISTRY:
        raise GiftInputError(f"{where}: unknown effect {name!r}; known: {', '.join(REGISTRY)}")
    cls = REGISTRY[name]
    unknown = set(values) - set(cls.params) - set(cls.static_fields)
    if unknown:
        raise GiftInputError(f"{where}: effect {name} has no parameter {sorted(unknown)[0]!r}; "
                             f"it takes {', '.join(cls.params) or 'none'}")
    kwargs = {p: _coerce(cls, p, values.get(p, cls.defaults.get(p, 0.0)), where) for p in cls.params}
    kwargs.update({f: values[f] for f in cls.static_fields if f in values})
    return cls(**kwargs).validate(where)


def parse_effect(spec: str, where: str = "effect") -> Effect:
    """Parse ``NAME``, ``NAME=VALUE``, ``NAME=V1,V2`` or ``NAME=p:V,p:V``.

    Examples: ``awgn=0.1``, ``laplace``, ``shot=0.01``, ``quantization=6,1.0``,
    ``quantization=bits:6,v_range:1``.
    """
    spec = spec.strip()
    name, _, rest = spec.partition("=")
    name = name.strip()
    if name not in REGISTRY:
        raise GiftInputError(f"{where}: unknown effect {name!r} in {spec!r}; known: {', '.join(REGISTRY)}")
    cls = REGISTRY[name]
    values: dict = {}
    if rest.strip():
        parts = [p.strip() for p in rest.split(",") if p.strip()]
        for i, part in enumerate(parts):
            if ":" in part:
                key, _, val = part.partition(":")
                key = key.strip()
            else:
                if i >= len(cls.params):
                    raise GiftInputError(f"{where}: {spec!r} gives {len(parts)} values, {name} takes "
                                         f"{len(cls.params)} ({', '.join(cls.params) or 'none'})")
                key, val = cls.params[i], part
            try:
                values[key] = float(val)
            except ValueError:
                raise GiftInputError(f"{where}: {spec!r}: {val!r} is not a number") from None
    elif cls.params and name != "awgn":
        missing = [p for p in cls.params if p not in cls.defaults]
        if missing:
            raise GiftInputError(f"{where}: {spec!r} needs a value for {', '.join(missing)}")
    return make_effect(name, where, **values)
