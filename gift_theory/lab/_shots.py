"""Stage 1 of the lab: a model of the device and its shots for a measurement's inputs.

A :class:`Model` is the core's generative process (reference §2) with the physics it believes
and the weights it believes are programmed. Its shots come from the core: standard draws of
:func:`gift_theory.sample_noise` (the physics' own noise law, each site from its own named
subkey, so the draws of a site are common to every candidate model) through
:func:`gift_theory.forward`. There is no second simulator in the lab.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
import threading

import jax
import jax.numpy as jnp
import numpy as np

from .. import _random
from .._finite import check_all_finite, check_finite
from .._measurement import Measurement
from .._model import (
    compiled_draws,
    compiled_site_draws,
    flat_law,
    forward,
    layer_step,
    name_tag,
    named_subkey,
    noise_law,
    noisy_input,
    site_draw_bytes,
    site_laws,
)
from .._params import Layer, params32, to32  # noqa: F401  (the lab's modules import them from here)


@dataclasses.dataclass(frozen=True)
class Model:
    """A model of the device: physics plus the weights it believes are programmed.

    physics : :class:`gift_theory.Physics`
    params : the weights the model runs with; None: the measurement's programmed weights.
        They differ from the programmed ones when an effect fitted as per-device offsets
        (``weight_error``: ``W + E_hat``, ``bias_offset``: ``b + delta_hat``) was estimated.
    offsets : ``{effect name: fitted prior scale}`` of the effects fitted as offsets (their
        per-device values live in ``params``)
    """

    physics: object
    params: tuple | None = None
    offsets: dict = dataclasses.field(default_factory=dict)

    @property
    def effects(self) -> list[str]:
        return list(self.physics.names) + [n for n in self.offsets if n not in self.physics.names]

    def params_json(self) -> dict:
        out = {}
        for k, v in self.physics.params().items():
            a = np.asarray(v if not isinstance(v, (tuple, list)) else np.concatenate([np.ravel(x) for x in v]))
            out[k] = float(a) if a.ndim == 0 else [float(x) for x in a.ravel()]
        out.update({k: float(v) for k, v in self.offsets.items()})
        return out

    def describe(self) -> str:
        d = self.physics.describe()
        for name, scale in self.offsets.items():
            if name not in self.physics:  # a per-neuron parameter shows in the physics itself
                d += f" + {name}(scale={scale:.4g}, fitted offsets)"
        return d

    def weights(self, meas: Measurement) -> tuple:
        return self.params if self.params is not None else meas.params


def default_model_shots(r: int) -> int:
    """Model shots per input when not told: 4 r (the model's own sampling noise in the
    statistic then is a quarter of the data's, so candidates differ by physics, not luck)."""
    return 4 * int(r)


def tiled_times(meas: Measurement, K: int):
    """The measured acquisition times tiled to K model shots per input (n, K), or None."""
    return None if meas.t is None else to32(_tiled(meas, K))


def _tiled(meas: Measurement, K: int) -> np.ndarray:
    """:func:`tiled_times` on the host, in the file's precision."""
    return np.tile(meas.t, (1, -(-K // meas.r)))[:, :K]


#: bytes of standard draws kept between calls (least recently used first out)
DRAW_CACHE_BYTES = 64 << 20
_draw_cache: "collections.OrderedDict[tuple, tuple]" = collections.OrderedDict()  # key -> (draws, bytes held)
_draw_lock = threading.Lock()
_draw_bytes = [0]


def draws(key, physics, meas: Measurement, K: int) -> dict:
    """Standard draws of ``physics`` for K shots of each input of ``meas`` (the core's sampler).

    A site's draws depend on the key, its name and shape and, at additive sites, the noise
    law -- not on the other effects -- so every candidate model of a diagnosis reuses the
    draws of the sites it shares with the others: they are kept per site (up to
    :data:`DRAW_CACHE_BYTES`), bit for bit what :func:`gift_theory._model.compiled_draws`
    returns for the whole physics (both draw through :func:`gift_theory._model.compiled_site_draws`).
    A law with parameters cannot key the cache (its draws depend on their values): such a
    physics is drawn whole."""
    shape = (meas.n, int(K))
    law = noise_law(physics)
    if law is not None and law.param_dict():
        return compiled_draws(key, physics, arch=meas.arch, shape=shape, dtype=jnp.float32)
    kd = np.asarray(jax.random.key_data(key)).tobytes()
    out = {}
    for name, (event, site_law) in site_laws(meas.arch, physics).items():
        full = shape + event
        ck = (kd, name, full, None if site_law is None else site_law.name)
        with _draw_lock:
            v = _draw_cache.get(ck)
            if v is not None:
                _draw_cache.move_to_end(ck)
                v = v[0]
        if v is None:
            v = compiled_site_draws(key, name, full, site_law, jnp.float32)
            with _draw_lock:
                if ck not in _draw_cache:  # counted as held: a padded program's whole output
                    _draw_cache[ck] = (v, site_draw_bytes(full, site_law, jnp.float32))
                    _draw_bytes[0] += _draw_cache[ck][1]
                while _draw_bytes[0] > DRAW_CACHE_BYTES and len(_draw_cache) > 1:
                    _draw_bytes[0] -= _draw_cache.popitem(last=False)[1][1]
        out[name] = v
    return out


@functools.partial(jax.jit, static_argnames=("arch",))
def layer_outputs(params, x, noise, physics, arch, t):
    """Every layer's output a_1..a_L for inputs x (n, d_0) and draws of batch (n, K)
    (jitted core ``forward``; compiled once per physics structure and shape, shared by the
    fit and the comparison)."""
    return forward(params, x[:, None, :], noise, physics, arch, t=t, taps=True).taps


def model_shots(key, model: Model, meas: Measurement, shots: int | None = None):
    """Shots of the model for the measurement's inputs (and times): one (n, K, d_l) array per
    measured layer (taps then output). ``K = shots`` (default 4 r); times are the measured
    ones, tiled when K exceeds r. Drawn in chunks of 2 r shots (the fit's shape: one
    compiled program serves both), chunk c from ``fold_in(key, c)``."""
    K = default_model_shots(meas.r) if shots is None else int(shots)
    return _shots_of_rows(key, model, meas, K, 0, meas.n,
                          lambda k, chunk: draws(k, model.physics, meas, chunk))


def padded_rows(v, i0: int, i1: int, size: int):
    """Rows ``i0:i1`` of ``v``, the last row repeated up to ``size`` rows: a block of a larger
    array's inputs in the block's compiled shape (the padding rows are computed and dropped).
    A numpy array is sliced on the host, a JAX array on the device; the whole array, in one
    block, is ``v`` itself."""
    if i0 == 0 and i1 == size == v.shape[0]:
        return v
    xp = np if isinstance(v, np.ndarray) else jnp
    part = v[i0:i1]
    if i1 - i0 < size:
        part = xp.concatenate([part, xp.repeat(v[i1 - 1:i1], size - (i1 - i0), axis=0)], axis=0)
    return part


def _host_rows(a, start: int, k: int, size: int):
    """Rows ``start .. start + k - 1`` of the host array ``a`` as float32 on the device, padded to
    ``size`` rows (:func:`padded_rows`)."""
    return to32(padded_rows(np.asarray(a), start, start + k, size))


def _shots_of_rows(key, model: Model, meas: Measurement, K: int, start: int, size: int, noise_of):
    """:func:`model_shots` of inputs ``start .. start + size - 1``, shot chunk c drawn by
    ``noise_of(fold_in(key, c), chunk)`` for those rows; rows past the last input are padding
    (computed in the block's compiled shape, not returned)."""
    params = params32(model.weights(meas))
    chunk = 2 * meas.r if K % (2 * meas.r) == 0 else K
    k = min(size, meas.n - start)
    x = _host_rows(meas.x, start, k, size)
    t = None if meas.t is None else _host_rows(_tiled(meas, chunk), start, k, size)
    physics = strong32(model.physics)  # the fit's leaf types: its compiled forward serves here
    ids = meas.layer_ids()
    outs = None
    for c in range(K // chunk):
        noise = noise_of(jax.random.fold_in(key, c), chunk)
        part = layer_outputs(params, x, noise, physics, meas.arch, t)
        part = part if k == size else tuple(a[:k] for a in part)
        check_all_finite(part, [lambda l=l: f"the model's shots of layer {l} ({model.describe()})"
                                for l in range(1, len(part) + 1)],
                         lambda kk, i: eager_forward_at(params, x, noise, physics, meas.arch, t, i))
        if K == chunk:
            return tuple(part[l - 1] for l in ids)
        if outs is None:  # filled part by part: a concatenation held every part and the whole at once
            outs = [np.empty((k, K, part[l - 1].shape[-1]), np.float32) for l in ids]
        for o, l in zip(outs, ids):
            o[:, c * chunk:(c + 1) * chunk] = np.asarray(part[l - 1])
        del part, noise
    return tuple(outs)


def _site_rows(key, name: str, full: tuple, site_law, start: int, size: int):
    """Rows ``start .. start + size - 1`` of one site's draws of shape ``full`` (the draws of
    :func:`draws`, bit for bit), or None where they cannot be made alone: a plugin's law, or a
    draw whose words (with the block's padding) pass the 2^32 a block's word index can count."""
    law = flat_law(site_law, jnp.float32)  # a built-in law's name in _random, None for a plugin's
    if law is None or not _random.rows_fit(full, start, size) or math.prod(full) >= 2 ** 32:
        return None
    return _random.rows(law, jax.random.fold_in(key, np.uint32(name_tag(name))), full, start, size)


def draw_rows(key, physics, meas: Measurement, K: int, start: int, size: int) -> dict:
    """Inputs ``start .. start + size - 1`` of :func:`draws` (key, physics, meas, K), bit for bit,
    made without the other inputs' draws; rows past the last input are padding. A law with
    parameters or from a plugin is drawn whole and sliced (the same numbers, no memory saved)."""
    law = noise_law(physics)
    whole = law is not None and law.param_dict()
    out, every = {}, None
    for name, (event, site_law) in site_laws(meas.arch, physics).items():
        v = None if whole else _site_rows(key, name, (meas.n, int(K)) + tuple(event), site_law, start, size)
        if v is None:
            every = draws(key, physics, meas, K) if every is None else every
            v = padded_rows(every[name], start, min(start + size, meas.n), size)
        out[name] = v
    return out


#: bytes of a block of model shots (every measured layer, float32) that :func:`shot_blocks` makes
#: at a time: a larger draw is made and used a block of inputs at a time
SHOT_BLOCK_BYTES = 16 << 20


def block_inputs(meas: Measurement, K: int) -> int:
    """Inputs per block of :func:`shot_blocks` for K model shots per input: all of them when
    their shots fit in :data:`SHOT_BLOCK_BYTES`."""
    per_input = 4 * int(K) * sum(meas.arch.widths[l] for l in meas.layer_ids())
    return int(max(1, min(meas.n, SHOT_BLOCK_BYTES // max(per_input, 1))))


def shot_blocks(key, model: Model, meas: Measurement, shots: int | None = None):
    """:func:`model_shots` a block of inputs at a time: yields ``(slice, shots)`` with ``shots``
    the block's rows of every measured layer's (n, K, d_l) model shots, bit for bit (each
    input's draws are made alone, :func:`draw_rows`, and the forward pass acts input by input),
    so a statistic computed input by input needs :func:`block_inputs` inputs' shots at once, not
    the whole array. One block when they fit (then the shots are :func:`model_shots`' own)."""
    K = default_model_shots(meas.r) if shots is None else int(shots)
    B = block_inputs(meas, K)
    if B >= meas.n:
        yield slice(0, meas.n), model_shots(key, model, meas, shots)
        return
    for i0 in range(0, meas.n, B):  # the last block padded: one compiled program serves every block
        yield slice(i0, min(i0 + B, meas.n)), _shots_of_rows(
            key, model, meas, K, i0, B, lambda k, chunk: draw_rows(k, model.physics, meas, chunk, i0, B))


def eager_forward_at(params, x, noise, physics, arch, t, at=None):
    """The forward pass of a batch of draws ``noise`` run again eagerly (the failure path of a
    non-finite stage; ``at``, the first bad index, is not needed: a hook's fault may depend on the
    whole batch): every plugin hook's result is then checked as it returns, and a hook that
    returned NaN or inf is named in one line."""
    with jax.disable_jit():
        forward(params, jnp.asarray(x)[:, None, :], noise, physics, arch, t=None if t is None else jnp.asarray(t),
                taps=True)


def strong32(physics):
    """``physics`` with every parameter a float32 array: a Python float is a weakly typed leaf,
    and a jitted function called with both kinds compiles twice (``physics.replace(s=0.1)``
    against a fitted s: a fresh process compiled every layer's one-step program twice)."""
    return jax.tree_util.tree_map(lambda v: np.asarray(v, np.float32), physics)


def _one_step(key, W, b, a, physics, t, arch, layer, q):
    """Layer ``layer``'s model shots fed ``a``: the draws of the sites that layer reads
    (:func:`_step_sites`) by the programs of their padded lengths, then the step itself, so a new
    shape or physics compiles only the step."""
    shape = a.shape[:2] + ((q,) if q else ())
    noise = compiled_draws(key, physics, arch=arch, shape=shape, dtype=jnp.float32,
                           sites=_step_sites(W, b, a, physics, t, arch, layer, q))
    return _one_step_forward(W, b, a, noise, physics, t, arch, layer, q)


def _step(W, b, a, noise, physics, t, arch, layer, q):
    if q:  # q draws per measured shot: the measured input and time repeat
        a = a[:, :, None, :]
        t = None if t is None else t[:, :, None] * jnp.ones((1, 1, q), t.dtype)
    if layer == 1:
        a = noisy_input(a, noise, physics)
    out = layer_step(W, b, a, noise, physics, arch, layer, t=t)[0]
    # draw-major: block j holds draw j of every measured shot, so each block of r shots has the
    # measured input's spread, like the measured shots themselves
    return jnp.swapaxes(out, 1, 2).reshape(out.shape[0], -1, out.shape[-1]) if q else out


_one_step_forward = functools.partial(jax.jit, static_argnames=("arch", "layer", "q"))(_step)


class _Asked(dict):
    """Draws that note the names a step asks for (``[]``, ``get``, ``in``); a step that lists
    them (iteration, ``keys``, ``items``, ``values``, ``len``) is noted as asking for all."""

    def __init__(self, *args):
        super().__init__(*args)
        self.asked, self.every = set(), False

    def __getitem__(self, name):
        self.asked.add(name)
        return super().__getitem__(name)

    def get(self, name, default=None):
        self.asked.add(name)
        return super().get(name, default)

    def __contains__(self, name):
        self.asked.add(name)
        return super().__contains__(name)

    def _all(self, method, *args):
        self.every = True
        return getattr(super(), method)(*args)

    def __iter__(self):
        return self._all("__iter__")

    def __len__(self):
        return self._all("__len__")

    def keys(self):
        return self._all("keys")

    def items(self):
        return self._all("items")

    def values(self):
        return self._all("values")


_sites_memo: dict = {}


def _step_sites(W, b, a, physics, t, arch, layer, q):
    """The draw sites one-step layer ``layer`` reads, found by tracing the step abstractly once
    per physics structure: a layer's step reads its own sites (and layer 1 the input's), and
    drawing the others would cost the draws of the whole network per check. Every name the step
    asked for or tested is kept, so a test of a name absent from the physics answers as before;
    a step that lists the draws, or a trace that fails, gets every site."""
    laws = site_laws(arch, physics)
    memo_key = (arch, layer, q, t is None, jax.tree_util.tree_structure(physics), tuple(laws))
    if memo_key in _sites_memo:
        return _sites_memo[memo_key]
    shape = a.shape[:2] + ((q,) if q else ())
    seen = []

    def probe(W, b, a, t):
        noise = _Asked({name: jnp.zeros(shape + tuple(event), jnp.float32) for name, (event, _) in laws.items()})
        _step(W, b, a, noise, physics, t, arch, layer, q)
        seen.append(noise)

    try:
        jax.eval_shape(probe, W, b, a, t)
        sites = None if seen[0].every else tuple(name for name in laws if name in seen[0].asked)
    except Exception:  # the step itself runs next and says what is wrong
        sites = None
    _sites_memo[memo_key] = sites
    return sites


def one_step_shots(key, model: Model, meas: Measurement, layer: int, draws: int = 0):
    """The model's layer ``layer`` fed with the *measured* output of the layer before, same
    shot (needs taps for layer >= 2; layer 1 is fed x and the model's input noise).

    Returns (n, r, d_l): model shot k fed measured shot k; with ``draws`` = q > 0, (n, q r, d_l):
    q model draws per measured shot, draw j of shot k at j r + k."""
    W, b = params32(model.weights(meas))[layer - 1]
    if layer == 1:
        a = to32(np.broadcast_to(np.asarray(meas.x)[:, None, :], (meas.n, meas.r, meas.x.shape[1])))
    else:
        a = to32(meas.taps[layer - 2])
    t = None if meas.t is None else to32(meas.t)
    phys = strong32(model.physics)
    out = _one_step(key, W, b, a, phys, t, meas.arch, layer, int(draws))
    check_finite(out, lambda: f"the one-step shots of layer {layer} ({model.describe()})",
                 lambda i: _eager_one_step(key, W, b, a, phys, t, meas.arch, layer, int(draws)))
    return out


def one_step_block_inputs(meas: Measurement, layers, draws: int) -> int:
    """Inputs per block of :func:`one_step_rows` for the one-step shots of ``layers`` with
    ``draws`` model draws per measured shot (float32): all of them when they fit in
    :data:`SHOT_BLOCK_BYTES`."""
    per_input = 4 * max(int(draws), 1) * meas.r * sum(meas.arch.widths[l] for l in layers)
    return int(max(1, min(meas.n, SHOT_BLOCK_BYTES // max(per_input, 1))))


def one_step_rows(key, model: Model, meas: Measurement, layer: int, draws: int, start: int, size: int):
    """Inputs ``start .. start + size - 1`` of :func:`one_step_shots` (key, model, meas, layer,
    draws), bit for bit, made without the other inputs' draws (each site's rows, as
    :func:`draw_rows` makes them; a law with parameters or a plugin's is drawn whole and sliced)
    by the program of a block of ``size`` inputs (the last block padded)."""
    W, b = params32(model.weights(meas))[layer - 1]
    k = min(size, meas.n - start)
    if layer == 1:
        x = _host_rows(meas.x, start, k, size)
        a = jnp.broadcast_to(x[:, None, :], (size, meas.r, x.shape[1]))
    else:
        a = _host_rows(meas.taps[layer - 2], start, k, size)
    t = None if meas.t is None else _host_rows(meas.t, start, k, size)
    phys, q = strong32(model.physics), int(draws)
    full = (meas.n, meas.r) + ((q,) if q else ())
    sites = _step_sites(W, b, a, phys, t, meas.arch, layer, q)
    laws = site_laws(meas.arch, phys)
    law = noise_law(phys)
    whole = law is not None and law.param_dict()
    noise, every = {}, None
    for name in (laws if sites is None else sites):
        event, site_law = laws[name]
        v = None if whole else _site_rows(key, name, full + tuple(event), site_law, start, size)
        if v is None:
            if every is None:
                every = compiled_draws(key, phys, arch=meas.arch, shape=full, dtype=jnp.float32, sites=sites)
            v = padded_rows(every[name], start, start + k, size)
        noise[name] = v
    out = _one_step_forward(W, b, a, noise, phys, t, meas.arch, layer, q)
    out = out if k == size else out[:k]
    check_finite(out, lambda: f"the one-step shots of layer {layer} ({model.describe()})",
                 lambda i: _eager_one_step(key, W, b, a, phys, t, meas.arch, layer, q))
    return out


def _eager_one_step(key, W, b, a, physics, t, arch, layer, q):
    """:func:`_one_step` again, eagerly (a plugin hook that returned a non-finite value is named
    where it returns)."""
    with jax.disable_jit():
        _one_step(key, W, b, a, physics, t, arch, layer, q)


def one_step_pre(model: Model, meas: Measurement, layer: int) -> np.ndarray:
    """Layer ``layer``'s noiseless pre-activation (n, d_l) fed with the mean over shots of the
    measured layer before (x for layer 1)."""
    W, b = params32(model.weights(meas))[layer - 1]
    a = meas.x if layer == 1 else np.mean(meas.taps[layer - 2], axis=1)
    return np.asarray(_one_step_pre(W, b, to32(a), strong32(model.physics), layer,
                                    meas.arch.depth), np.float64)


@functools.partial(jax.jit, static_argnames=("layer", "depth"))
def _one_step_pre(W, b, a, physics, layer, depth):
    return a @ physics.effective_weights(W, layer, depth).T + physics.bias(b, layer, depth)


def noiseless_pre(model: Model, meas: Measurement):
    """The model's noiseless pre-activations z_l (n, d_l) of every layer, through the core's
    forward pass with every draw zero (every effect's hooks apply; gains at 1 + 0)."""
    return _noiseless_of(model, meas, model.physics)[0]


def noiseless_taps(model: Model, meas: Measurement, physics=None):
    """The noiseless outputs a_l (n, d_l) of every layer, every draw zero (float64 numpy), under
    ``physics`` (default the model's)."""
    return _noiseless_of(model, meas, model.physics if physics is None else physics)[1]


def _noiseless_of(model: Model, meas: Measurement, physics):
    """(pre-activations, outputs) of every layer, every draw zero, as float64 numpy lists."""
    p32, x32, phys = params32(model.weights(meas)), to32(meas.x), strong32(physics)
    pre, taps = _noiseless(p32, x32, phys, meas.arch)

    def rerun(k, i):
        with jax.disable_jit():
            _noiseless(p32, x32, phys, meas.arch)
    check_all_finite(taps, [lambda l=l: f"the noiseless output of layer {l} ({physics.describe()})"
                            for l in range(1, len(taps) + 1)], rerun)
    return [np.asarray(z, np.float64) for z in pre], [np.asarray(a, np.float64) for a in taps]


@functools.partial(jax.jit, static_argnames=("arch",))
def _noiseless(params, x, physics, arch):
    """(pre-activations, outputs) of every layer with every draw zero, in one program (op by op
    the core's forward was some thirty dispatched programs a diagnosis traced)."""
    noise = {k: jnp.zeros((x.shape[0], 1) + tuple(ev), jnp.float32) for k, ev in physics.draws(arch).items()}
    out = forward(params, x[:, None, :], noise, physics, arch, t=None, taps=True)
    return [z[:, 0] for z in out.pre], [a[:, 0] for a in out.taps]


@functools.partial(jax.jit, static_argnames=("sigma",))
def central_slope(z, sigma, h: float = 1e-3):
    """(sigma(z + h) - sigma(z - h)) / (2 h) in one program (float32)."""
    return (sigma(z + h) - sigma(z - h)) / (2 * h)


__all__ = ["Model", "to32", "params32", "default_model_shots", "tiled_times", "draws", "layer_outputs", "model_shots",
           "one_step_shots", "noiseless_pre", "noiseless_taps", "central_slope", "named_subkey"]
