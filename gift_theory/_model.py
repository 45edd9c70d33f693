"""The ONN model M_s and its generalisation with physical effects.

Paper eqs. def:matrices-Ai and def:matrix-AL; reference §1-2, §2b::

    a_0 = x + n_a0
    u_l = W_l^eff a_{l-1}
    z_l = g_l u_l + b_l^eff + n_wl              l = 1..L
    a_l = D(act_l(z_l) + n_al)                  l = 1..L-1
    M_s(x, w, N) = a_L = D(z_L)

with W^eff, b^eff, g, act (sigma by default) and D given by the physics' effects acting
on layer l (:class:`~gift_theory.effects.Physics`).

Randomness enters only through a dict of *standard* draws (unit variance; the law of
the additive ones set by the physics), which the forward pass scales: additive noise is
``s * xi``. So the output is a deterministic, differentiable function of
``(params, physics parameters, x, draws)`` -- pathwise derivatives in s or any effect
parameter are plain autodiff, and common random numbers are reusing the same draws.
Everything is batched over leading axes: ``x`` of shape (..., d_0) broadcasts against
draws of shape (batch..., d_l), e.g. x of shape (K1, 1, d_0) with draws of shape
(K1, K2, d_l) gives the hierarchical K1 x K2 design without copying x.
"""

from __future__ import annotations

import zlib
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _random, _xla
from ._arch import Architecture
from ._errors import GiftInputError
from .effects import Physics


def name_tag(name: str) -> int:
    """The integer a name folds into a key (:func:`named_subkey`)."""
    return zlib.crc32(name.encode()) & 0x7FFFFFFF


def named_subkey(key: jax.Array, name: str) -> jax.Array:
    """A subkey that depends only on ``name`` (stable when other names are added)."""
    return jax.random.fold_in(key, name_tag(name))


def noise_law(physics: Physics):
    """The physics' noise-law effect (stage ``law``), None for the Gaussian law."""
    return next((e for e in physics.effects if e.stage == "law"), None)


def site_layer(name: str) -> int:
    """The layer an additive site belongs to: ``w{l}`` and ``a{l}`` layer l, the input ``a0`` 0."""
    return int(name[1:])


def _law_at(law, name: str, depth: int) -> bool:
    """Whether the noise law ``law`` draws the additive site ``name``: every site under the scope
    ``"all"``; else the sites ``w_l``, ``a_l`` of the layers in its scope (never the input's)."""
    if law.layers == "all":
        return True
    layer = site_layer(name)
    return layer >= 1 and law.acts_on(layer, depth)


def site_laws(arch: Architecture, physics: Physics) -> dict:
    """``{site name: (event shape, law)}``: every draw site of ``physics`` and how it is drawn --
    ``law`` the noise-law effect at an additive site (``a0``, ``w{l}``, ``a{l}``) in its scope
    (``layers``), None (standard normal) everywhere else."""
    additive = set(_additive_names(arch)) if "awgn" in physics else set()
    law = noise_law(physics)
    return {name: (tuple(event), law if name in additive and law is not None and _law_at(law, name, arch.depth)
                   else None)
            for name, event in physics.draws(arch).items()}


def site_draws(key: jax.Array, name: str, shape: tuple, law=None, dtype=jnp.float32) -> jax.Array:
    """One site's standard draws: from the site's own named subkey, the law's unit-variance
    draws (``law``: a noise-law effect) or standard normal (None). The one per-site sampler:
    :func:`sample_noise` and the lab's per-site draw cache both draw through it. Called outside
    a traced function, a built-in law's float32 draws come from the program of their padded
    length (:func:`compiled_site_draws`: the same numbers, no program per shape)."""
    if not isinstance(key, jax.core.Tracer) and _random._eager():  # gift's own stream: any key kind, 64-bit mode too
        flat = _padded_site_draws(key, name, shape, law, dtype)
        if flat is not None:
            return flat
    return tagged_draws(key, name_tag(name), shape, law, dtype)  # a site's draws are named by the site


def tagged_draws(key: jax.Array, tag, shape: tuple, law=None, dtype=jnp.float32) -> jax.Array:
    """:func:`site_draws` with the site's name given as its tag (:func:`name_tag`), which may be
    traced: one compiled program then serves every site of the same shape and law."""
    k = jax.random.fold_in(key, tag)
    if law is None:
        return _random.normal(k, shape, dtype)
    return _law_draws(law, k, shape, dtype)


def _law_draws(law, k, shape, dtype):
    """A noise law's unit-variance draws; a plugin law that raises is a bad input (one line)."""
    from .effects._base import _is_builtin
    from .effects._physics import plugin_failure_line

    if _is_builtin(type(law)):
        return law.standard(k, shape, dtype)
    try:
        out = law.standard(k, shape, dtype)
    except GiftInputError:
        raise
    except Exception as exc:
        raise GiftInputError(plugin_failure_line(type(law), "standard", exc)) from None
    from .effects._physics import checked_result

    out = checked_result(type(law), "standard", out, tuple(shape), jnp.zeros((), dtype))
    if tuple(out.shape) != tuple(shape):  # the draws of every site, shot and neuron: no broadcasting
        raise GiftInputError(f"{plugin_failure_line(type(law), 'standard', None)}: returned shape "
                             f"{tuple(out.shape)}, expected {tuple(shape)}")
    return out


def sample_noise(key: jax.Array, arch: Architecture, physics: Physics, batch_shape=(), dtype=jnp.float32) -> dict:
    """Standard draws for ``batch_shape`` shots: ``{name: array of shape batch_shape + event}``.

    Additive sites (``a0``, ``w{l}``, ``a{l}``) follow the physics' noise law with unit
    variance; every other draw is standard normal (all from :mod:`gift_theory._random`). Each name has its own subkey, so the
    draws of a site do not change when other effects are added (common random numbers).
    """
    batch_shape = tuple(batch_shape)
    return {name: site_draws(key, name, batch_shape + event, law, dtype)
            for name, (event, law) in site_laws(arch, physics).items()}


#: :func:`tagged_draws` as a compiled program with the tag traced: one program per shape, law and
#: dtype draws every site of that shape, whatever the physics around it (the draws of a site
#: depend only on the key, its name, shape and law); :func:`compiled_site_draws` uses it where a
#: program of a padded length cannot serve (a plugin's law, float64, a draw above the cap)
_site_program = _xla.jit(tagged_draws, static_argnames=("shape", "law", "dtype"))


#: the built-in noise laws (by effect name; None: the standard normal) whose draws are made apart
#: from their shape: by a program of a padded size (:func:`gift_theory._random.tagged_flat`) or a
#: block of rows at a time (:func:`gift_theory._random.rows`, the lab's shot blocks)
FLAT_LAWS = {None: "normal", "laplace": "laplace", "uniform": "uniform_law"}


def flat_law(law, dtype) -> str | None:
    """The :data:`gift_theory._random.ROW_LAWS` name of a site's law when its float32 draws can be
    made apart from their shape (a built-in law, or None), else None (a plugin's law)."""
    from .effects._base import _is_builtin

    if jnp.dtype(dtype) != jnp.float32:
        return None
    if law is None:
        return FLAT_LAWS[None]
    return FLAT_LAWS.get(law.name) if _is_builtin(type(law)) else None


def compiled_site_draws(key: jax.Array, name: str, shape: tuple, law=None, dtype=jnp.float32) -> jax.Array:
    """:func:`site_draws` by a compiled program that draws of other shapes share.

    On the CPU a float32 draw of a built-in law up to :data:`gift_theory._random.PADDED_MAX_WORDS`
    words is made by the program of its padded length (:func:`gift_theory._random.padded_size`:
    the 22 site shapes of a small diagnosis need 14 programs) and its first words reshaped,
    without a copy; any other draw by the
    program of its own shape, law and dtype. The numbers are the same either way, bit for bit."""
    flat = _padded_site_draws(key, name, shape, law, dtype)
    if flat is not None:
        return flat
    return _site_program(key, np.uint32(name_tag(name)), tuple(int(d) for d in shape), law, dtype)


def _padded_length(shape, law, dtype) -> int | None:
    """The padded length of the program that draws a site of ``shape`` (:func:`_padded_site_draws`),
    or None where a program of the site's own shape draws it."""
    n = int(np.prod(tuple(int(d) for d in shape), dtype=np.int64))
    if flat_law(law, dtype) is None or n <= 0 or jax.default_backend() != "cpu":
        return None
    return _random.padded_size(n)


def site_draw_bytes(shape, law=None, dtype=jnp.float32) -> int:
    """The bytes a site's draws of :func:`compiled_site_draws` hold: a padded program's whole
    output (the draws are a view of it), else the draws' own."""
    size = _padded_length(shape, law, dtype)
    n = size if size is not None else int(np.prod(tuple(int(d) for d in shape), dtype=np.int64))
    return int(n) * jnp.dtype(dtype).itemsize


def _padded_site_draws(key, name: str, shape, law, dtype):
    """A site's float32 draws of a built-in law by the program of their padded length, or None
    where that program cannot make them (a plugin's law, float64, too many words, off the CPU)."""
    shape = tuple(int(d) for d in shape)
    size = _padded_length(shape, law, dtype)
    if size is None:
        return None
    n = int(np.prod(shape, dtype=np.int64))
    flat = _random.tagged_flat(flat_law(law, dtype), key, name_tag(name), n, size)
    return jax.device_put(np.asarray(flat)[:n].reshape(shape))  # a view of the program's output


def compiled_draws(key, physics, *, arch, shape, dtype, sites=None):
    """:func:`sample_noise` made by compiled programs (materialised draws), bit for bit.

    Each site is drawn by :func:`compiled_site_draws`, so one program per padded length (or site
    shape) and law serves every physics structure, estimator, the referee, the objective and the lab (a whole-physics
    sampler compiled one program per structure: the threefry rounds of every site again). A
    noise law with parameters is drawn by one program of the whole physics (its values are
    arguments, not part of a program's key). The draws are compiled apart from the kernels that
    consume them: fused into a kernel, XLA recomputes them in every consumer, and compiles the
    sampler again into every kernel's program. ``sites``: only these names (default every site
    of the physics). Called inside a traced function, the draws are traced with it
    (:func:`sample_noise`: a traced key cannot key a program of its own).
    """
    laws = site_laws(arch, physics)
    if sites is not None:
        laws = {name: laws[name] for name in sites}
    if isinstance(key, jax.core.Tracer) or not _random._eager():
        return {name: tagged_draws(key, name_tag(name), tuple(shape) + tuple(event), site_law, dtype)
                for name, (event, site_law) in laws.items()}
    law = noise_law(physics)
    if law is not None and law.param_dict():
        every = _whole_draws(key, physics, arch=arch, shape=tuple(shape), dtype=dtype)
        return {name: every[name] for name in laws}
    return {name: compiled_site_draws(key, name, tuple(shape) + tuple(event), site_law, dtype)
            for name, (event, site_law) in laws.items()}


@partial(_xla.jit, static_argnames=("arch", "shape", "dtype"))
def _whole_draws(key, physics, *, arch, shape, dtype):
    """:func:`sample_noise` as one compiled program (a noise law with parameters)."""
    return sample_noise(key, arch, physics, shape, dtype)


def _additive_names(arch: Architecture):
    from .effects.awgn import additive_sites
    return additive_sites(arch).keys()


class Forward(NamedTuple):
    """Output of :func:`forward`.

    y : (..., d_L) the output a_L = M_s(x, w, N)
    taps : tuple of L arrays, a_1 .. a_L (each (..., d_l)); empty unless asked
    pre : tuple of L arrays, the pre-activations z_1 .. z_L; empty unless asked
    """

    y: jax.Array
    taps: tuple = ()
    pre: tuple = ()


def forward(params, x, noise: dict, physics: Physics, arch: Architecture, *, t=None,
            taps: bool = False) -> Forward:
    """One pass of the generative process for given standard draws.

    Parameters
    ----------
    params : tuple of Layer (W_l of shape (d_l, d_{l-1}), b_l of shape (d_l,))
    x : array of shape (..., d_0)
    noise : dict from :func:`sample_noise` (shapes broadcast against x's batch axes)
    physics : Physics
    arch : Architecture (static)
    t : None or array of shape (...,): normalised acquisition time of each shot
    taps : also return every layer's output and pre-activation

    Returns
    -------
    Forward
    """
    a = noisy_input(x, noise, physics)
    outs, pres = [], []
    for l, (W, b) in enumerate(params, start=1):
        a, z = layer_step(W, b, a, noise, physics, arch, l, t=t)
        if taps:
            outs.append(a)
            pres.append(z)
    return Forward(a, tuple(outs), tuple(pres))


def noisy_input(x, noise: dict, physics: Physics):
    """a_0 = x + n_a0: the input with the physics' input noise (x itself without one)."""
    return x + physics.s * noise["a0"] if "a0" in noise else x


def layer_step(W, b, a, noise: dict, physics: Physics, arch: Architecture, layer: int, *, t=None):
    """Layer ``layer`` of the generative process fed with ``a`` (its input a_{l-1}).

    ``u = W_eff a``, ``z = g u + b_eff + s n_w``, output ``D(act(z) + s n_a)`` (hidden;
    ``act`` the activation hooks composed around ``arch.sigma``) or ``D(z)`` (last layer),
    through the hooks of the physics' effects whose scope includes ``layer``. Used by
    :func:`forward` and by the measurement lab's one-step checks (``a`` the *measured*
    previous layer).

    Returns
    -------
    (output a_l, pre-activation z_l)
    """
    s = physics.s
    depth = arch.depth
    W = physics.effective_weights(W, layer, depth, t=t)
    # a time-dependent W_eff carries the shots' batch axes in front: one matrix per shot
    u = a @ W.T if W.ndim == 2 else jnp.matmul(W, a[..., None])[..., 0]
    g = physics.gain(noise, layer, t, u.shape, depth)
    z = (u if g is None else g * u) + physics.bias(b, layer, depth, t=t)
    if f"w{layer}" in noise:
        z = z + s * noise[f"w{layer}"]
    if layer < depth:
        out = physics.activation(z, arch.sigma, layer, depth, t=t)
        if f"a{layer}" in noise:
            out = out + s * noise[f"a{layer}"]
    else:
        out = z
    return physics.readout(out, noise, layer, depth, t=t), z


def simulate(key: jax.Array, params, x, physics: Physics, arch: Architecture, shots: int = 1, *, t=None,
             taps: bool = False) -> Forward:
    """``shots`` independent noisy passes per input (jitted).

    Parameters
    ----------
    key : PRNG key
    x : (n, d_0)
    shots : r
    t : None or (n, r) acquisition times

    Returns
    -------
    Forward with ``y`` of shape (n, r, d_L) and taps of shape (n, r, d_l).
    """
    return _simulate(key, params, jnp.asarray(x), physics, arch, int(shots), None if t is None else jnp.asarray(t),
                     bool(taps))


def _simulate(key, params, x, physics, arch, shots, t, taps):
    noise = compiled_draws(key, physics, arch=arch, shape=(x.shape[0], shots), dtype=params[0].W.dtype)
    return _simulate_forward(params, x, noise, physics, arch, t, taps)


@partial(jax.jit, static_argnames=("arch", "taps"))
def _simulate_forward(params, x, noise, physics, arch, t, taps):
    """:func:`simulate`'s forward pass on its draws: the draws are made by the programs of their
    padded lengths (:func:`compiled_draws`), so a new shape or physics compiles only this."""
    return forward(params, x[:, None, :].astype(params[0].W.dtype), noise, physics, arch, t=t, taps=taps)


def squared_error(y_pred, y):
    """The loss (y - M)^2 summed over outputs; shape (...,)."""
    return jnp.sum((y - y_pred) ** 2, axis=-1)
