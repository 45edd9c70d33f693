"""The physical-effect protocol and its composition (CONTRACTS §2).

A device and a model are both this generative process with extra effects::

    u_l = W_l^eff a_{l-1}                   (optical weighted sum)
    z_l = g_l * u_l + b_l + n_wl            (g_l: gain, 1 by default)
    a_l = D(sigma(z_l) + n_al)   (l < L),   y = a_L = D(z_L)
    D   = readout chain: saturation, then shot, then quantization

An :class:`Effect` is an immutable pytree: its physical parameters are leaves (so
they can be differentiated and fitted), its configuration is static. An effect acts
through at most one *stage* (``level``, ``law``, ``weights``, ``gain``, ``readout``);
:class:`Physics` applies the effects of a composition in the canonical order, so the
order in which a user lists them never matters.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import GiftInputError

#: name -> Effect subclass, filled by :func:`register`.
REGISTRY: dict[str, type["Effect"]] = {}

#: canonical stage order; inside a stage, the class attribute ``order``.
STAGES = ("level", "law", "weights", "gain", "readout")


def register(cls):
    """Class decorator: a frozen dataclass pytree, listed in :data:`REGISTRY`."""
    cls = dataclasses.dataclass(frozen=True)(cls)
    fields = [f.name for f in dataclasses.fields(cls)]
    meta = [f for f in fields if f in cls.static_fields]
    data = [f for f in fields if f not in cls.static_fields]
    jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)
    REGISTRY[cls.name] = cls
    return cls


class Effect:
    """Base class. Subclasses set the class attributes and override one hook.

    Class attributes
    ----------------
    name : the CONTRACTS §2 name, spelled exactly so.
    params : the names of its physical parameters (pytree leaves).
    bounds : per parameter, ``(low, high)``; the closed interval a value must lie in.
    defaults : a typical starting value per parameter (for fitting).
    stage : one of :data:`STAGES`.
    order : position inside the stage.
    static_fields : dataclass fields that are configuration, not parameters.
    """

    name: ClassVar[str]
    params: ClassVar[tuple[str, ...]] = ()
    bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    defaults: ClassVar[dict[str, float]] = {}
    stage: ClassVar[str]
    order: ClassVar[int] = 0
    static_fields: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""

    # ---- hooks (identity by default) -------------------------------------------
    def draws(self, arch) -> dict[str, tuple[int, ...]]:
        """Standard-normal draws this effect needs per shot: ``{key: event_shape}``."""
        return {}

    def weights(self, W: jax.Array, layer: int) -> jax.Array:
        """``weights`` stage: return W_eff for layer ``layer`` (1-based)."""
        return W

    def gain(self, noise: dict, layer: int, t, shape) -> jax.Array | float:
        """``gain`` stage: the factor g_l (broadcastable to ``shape``)."""
        return 1.0

    def readout(self, v: jax.Array, noise: dict, layer: int) -> jax.Array:
        """``readout`` stage: one link of the chain D."""
        return v

    # ---- helpers ------------------------------------------------------------------
    def param_dict(self) -> dict[str, float]:
        return {p: getattr(self, p) for p in self.params}

    def validate(self, where: str = "effect") -> "Effect":
        """Check the parameter values; raise :class:`GiftInputError` naming the first bad one."""
        for p in self.params:
            try:
                v = float(getattr(self, p))
            except (TypeError, ValueError):
                raise GiftInputError(f"{where}: {self.name} parameter {p} must be a number") from None
            lo, hi = self.bounds.get(p, (-float("inf"), float("inf")))
            if not (lo <= v <= hi) or v != v:
                raise GiftInputError(f"{where}: {self.name} parameter {p}={v:g} is outside [{lo:g}, {hi:g}]")
        return self


    # ---- what the measurement lab knows about it (fitting, ranking, signatures) -----
    #: fitted as per-device fixed offsets of the programmed weights ("W") or biases ("b"),
    #: with its (single) parameter the prior scale of those offsets (weight_error,
    #: bias_offset); None: its parameters are fitted by moment matching
    offsets_of: ClassVar[str | None] = None
    #: silent without acquisition times (a diagnosis tries it only on files that have them)
    needs_times: ClassVar[bool] = False

    @classmethod
    def search(cls, param: str, layers) -> np.ndarray:
        """Values of ``param`` a fit scans before refining them.

        Default, from the parameter's ``bounds`` and ``defaults``: a positive parameter (lower
        bound >= 0) 16 log-spaced values over [default / 1000, 30 default], a signed one 25
        evenly spaced values over +-15 |default|, both inside the bounds. ``layers``: the
        measured layer outputs (each (n, r, d_l)), for an effect whose scale is the data's.
        """
        lo, hi = cls.bounds.get(param, (-np.inf, np.inf))
        d = abs(float(cls.defaults.get(param, 1.0))) or 1.0
        if lo >= 0:
            vals = np.geomspace(d * 1e-3, d * 30.0, 16)
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
        the model's per-cell means, variances and shots. Returns ``{"statistic": str,
        "value": float, "z": float}`` with z ~ N(0, 1) under the model (a score test in the
        direction the effect would move the data); large positive z points at the effect.
        """
        return None

def make_effect(name: str, where: str = "effect", **values) -> Effect:
    """Build the effect ``name`` with parameter ``values`` (missing ones take defaults)."""
    if name not in REGISTRY:
        raise GiftInputError(f"{where}: unknown effect {name!r}; known: {', '.join(REGISTRY)}")
    cls = REGISTRY[name]
    unknown = set(values) - set(cls.params) - set(cls.static_fields)
    if unknown:
        raise GiftInputError(f"{where}: effect {name} has no parameter {sorted(unknown)[0]!r}; "
                             f"it takes {', '.join(cls.params) or 'none'}")
    kwargs = {p: float(values.get(p, cls.defaults.get(p, 0.0))) for p in cls.params}
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
