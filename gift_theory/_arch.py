"""The architecture of an ONN: widths, activation and where additive noise enters.

Paper, Section "Modeling ONNs" (eqs. def:matrices-Ai, def:matrix-AL); reference §1.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import jax.numpy as jnp

from ._errors import GiftInputError, require

#: activation functions by name; ``identity`` gives the deep linear case.
ACTIVATIONS: dict[str, Callable] = {
    "tanh": jnp.tanh,
    "identity": lambda z: z,
    "sigmoid": lambda z: 1.0 / (1.0 + jnp.exp(-z)),
    "sin": jnp.sin,
}

#: where additive noise enters.
#: ``all``: the paper's default -- input, every weighted sum, every hidden activation.
#: ``input``: the input only (the paper's linear example, Example 1).
NOISE_SITES = ("all", "input")


@dataclasses.dataclass(frozen=True)
class Architecture:
    """Widths ``d_0..d_L``, activation name and noise placement (static configuration).

    Parameters
    ----------
    widths : tuple of int, length L + 1
        ``(d_0, d_1, ..., d_L)``; layer ``l`` maps ``d_{l-1}`` to ``d_l``.
    activation : str
        A key of :data:`ACTIVATIONS` (``tanh`` unless told).
    noise_sites : {"all", "input"}
        Where the additive noise ``n_a0, n_wl, n_al`` enters.
    """

    widths: tuple[int, ...]
    activation: str = "tanh"
    noise_sites: str = "all"

    def __post_init__(self):
        widths = tuple(int(w) for w in self.widths)
        object.__setattr__(self, "widths", widths)
        require(len(widths) >= 2, f"architecture needs at least two widths (d_0 and d_L), got {widths}")
        require(all(w >= 1 for w in widths), f"architecture widths must be positive integers, got {widths}")
        require(self.activation in ACTIVATIONS,
                f"unknown activation {self.activation!r}; known: {', '.join(ACTIVATIONS)}")
        require(self.noise_sites in NOISE_SITES,
                f"unknown noise placement {self.noise_sites!r}; known: {', '.join(NOISE_SITES)}")

    @property
    def depth(self) -> int:
        """The number of layers ``L``."""
        return len(self.widths) - 1

    @property
    def sigma(self) -> Callable:
        return ACTIVATIONS[self.activation]

    @property
    def n_weights(self) -> int:
        """The number of weights ``sum_l d_l d_{l-1}`` (biases not counted)."""
        return sum(a * b for a, b in zip(self.widths[:-1], self.widths[1:]))

    @property
    def n_params(self) -> int:
        return self.n_weights + sum(self.widths[1:])

    @classmethod
    def parse(cls, spec: str | Sequence[int], activation: str = "tanh", noise_sites: str = "all") -> "Architecture":
        """Build from ``"64-32-16-10"`` or a sequence of widths."""
        if isinstance(spec, str):
            parts = spec.replace("x", "-").split("-")
            try:
                widths = tuple(int(p) for p in parts)
            except ValueError:
                raise GiftInputError(f"--arch {spec!r}: expected widths like 64-32-16-10") from None
        else:
            widths = tuple(spec)
        return cls(widths, activation, noise_sites)

    def __str__(self) -> str:
        return "-".join(str(w) for w in self.widths)
