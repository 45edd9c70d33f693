"""Fast counter-based draws for the model's noise: Threefry-2x32-20 written as fusible array ops.

Every Monte-Carlo number in gift is a noise draw, and on a CPU the draws, not the matrix
products, set the pace: ``jax.random.normal`` produces about 65 M float32 draws per second
on two cores (its Threefry lowering spends one cipher call per 32-bit word and does not
vectorise), so the 25 M draws of one K1 = 1024 x K2 = 8 estimate on the paper's deeper net
took longer than all of the estimate's matrix products. Here the same block cipher --
Threefry-2x32 with 20 rounds (Salmon et al., SC'11), bit for bit the one behind
``jax.random``'s default keys (tested against ``jax.extend.random.threefry_2x32``) -- is
written in plain integer array operations that XLA fuses into one vectorised loop, and
followed by Giles' float32 erfinv in the same loop: the 25 M draws take 0.039 s where
``jax.random.normal`` takes 0.4 s (with the estimators' 512-bit loops, gift_theory/_xla.py);
same key -> same numbers on every machine. The stream uses both 32-bit output words of every
cipher call, but XLA's loop emitter computes one output element at a time, so the loop
enciphers once per word (a kernel writing two elements per call would save ~20 %; XLA:CPU
does not form such multi-output loops here).

Stream layout: a draw of ``n`` words under key ``(k0, k1)`` enciphers the counters
``(c, 0)``, c = 0 .. ceil(n/2) - 1, and lays out the first output words, then the second
ones. Laws (all exactly symmetric about 0, never infinite):

* ``uniform``: ``(m + 1/2) 2^-22 - 1`` on (-1, 1), m the top 23 bits (float32) or
  ``(m + 1/2) 2^-51 - 1`` with m the top 52 bits of one cipher call (float64);
* ``normal``: ``sqrt(2) erfinv(uniform)`` (the transform ``jax.random.normal`` uses; in
  float32 Giles' erfinv written out in fused array operations);
* ``laplace``: unit variance, ``-sign(v) log(1 - |v|) / sqrt(2)`` for v uniform on (-1, 1);
* ``uniform_law``: unit variance, ``sqrt(3) v``.

Keys: any JAX key (typed or raw ``uint32``); the first two words of its data are the
cipher key (an ``rbg`` key made by tiling a Threefry key therefore draws the same numbers).

Where gift needs ``jax.random``'s own numbers (initial weights, inputs, teacher data, device
errors, the lab's splits and shuffles), :func:`uniform01`, :func:`uniform_like_jax`,
:func:`normal_like_jax`, :func:`permutation` and :func:`split_permutations` make them bit for
bit by programs of a padded length instead of JAX's program per shape (each compiles its
Threefry in about a second on a CPU); a traced call, 64-bit mode or a key whose bits are laid
out otherwise goes to ``jax.random`` itself.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import _xla

_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))
_PARITY = 0x1BD11BDA


def key_words(key) -> tuple[jax.Array, jax.Array]:
    """The two uint32 cipher-key words of a JAX key (typed or raw)."""
    if jnp.issubdtype(getattr(key, "dtype", np.uint32), jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    data = jnp.asarray(key).astype(jnp.uint32).reshape(-1)
    if data.shape[0] < 2:
        raise ValueError(f"a key needs at least two 32-bit words, got {data.shape[0]}")
    return data[0], data[1]


def _rotl(x, r: int):
    return (x << jnp.uint32(r)) | (x >> jnp.uint32(32 - r))


def threefry2x32(k0, k1, x0, x1):
    """The Threefry-2x32-20 block cipher on uint32 arrays ``(x0, x1)`` under key ``(k0, k1)``."""
    ks = (k0, k1, k0 ^ k1 ^ jnp.uint32(_PARITY))
    x0 = x0 + ks[0]
    x1 = x1 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x0 = x0 + x1
            x1 = _rotl(x1, r) ^ x0
        x0 = x0 + ks[(i + 1) % 3]
        x1 = x1 + ks[(i + 2) % 3] + jnp.uint32(i + 1)
    return x0, x1


def _pairs(key, n: int):
    """ceil(n/2) cipher calls: the two output words, each of shape (ceil(n/2),)."""
    if n >= 2 ** 33:
        raise ValueError(f"one draw of {n} words exceeds the 2^33 counter space; draw in blocks")
    k0, k1 = key_words(key)
    c = jax.lax.iota(jnp.uint32, max((n + 1) // 2, 1))
    return threefry2x32(k0, k1, c, jnp.zeros_like(c))


def bits(key, shape) -> jax.Array:
    """Uniform random uint32 words of ``shape``."""
    shape = tuple(int(d) for d in shape)
    n = math.prod(shape)
    y0, y1 = _pairs(key, n)
    return jnp.concatenate([y0, y1])[:n].reshape(shape)


def uniform(key, shape, dtype=jnp.float32) -> jax.Array:
    """Uniform draws on the open interval (-1, 1), exactly symmetric."""
    shape = tuple(int(d) for d in shape)
    dtype = jnp.dtype(dtype)
    n = math.prod(shape)
    if dtype == jnp.float64:
        y0, y1 = _pairs(key, 2 * n)  # one cipher call (64 bits) per float64 draw
        m = (y0.astype(jnp.uint64) << jnp.uint64(20)) | (y1.astype(jnp.uint64) >> jnp.uint64(12))
        u = (m.astype(jnp.float64) + 0.5) * (2.0 ** -51) - 1.0
        return u[:n].reshape(shape)
    if dtype not in (jnp.float32, jnp.float16, jnp.bfloat16):
        raise ValueError(f"uniform: unsupported dtype {dtype}")
    m = bits(key, shape) >> jnp.uint32(9)
    u = (m.astype(jnp.float32) + 0.5) * (2.0 ** -22) - 1.0
    return u.astype(dtype)


# Giles (2010), "Approximating the erfinv function", single precision: erfinv(u) = u p(w) with
# w = -log(1 - u^2) and p a degree-8 polynomial in w - 2.5 (w < 5) or sqrt(w) - 3 (w >= 5);
# the coefficients XLA's own float32 erfinv uses, highest degree first.
_ERFINV_CENTRAL = (2.81022636e-08, 3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087,
                   -0.00125372503, -0.00417768164, 0.246640727, 1.50140941)
_ERFINV_TAIL = (-0.000200214257, 0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773,
                -0.0076224613, 0.00943887047, 1.00167406, 2.83297682)


def _estrin8(c, t):
    """c[0] t^8 + ... + c[8] by Estrin's scheme: depth 4 instead of Horner's 8 dependent steps
    (XLA's CPU loops run one vector at a time, so a polynomial's latency, not its operation
    count, sets the pace)."""
    t2 = t * t
    t4 = t2 * t2
    lo = (c[8] + c[7] * t) + (c[6] + c[5] * t) * t2
    hi = (c[4] + c[3] * t) + (c[2] + c[1] * t) * t2
    return lo + hi * t4 + c[0] * (t4 * t4)


def _normal32(words):
    """uint32 words -> float32 standard normals sqrt(2) erfinv(u), u = (m + 1/2) 2^-22 - 1.

    With a = 1 + u = (2m + 1) 2^-23 (exact in float32), 1 - u^2 = a (2 - a) is a product of
    two exact factors, so w needs one rounding and one log instead of log1p(-u^2)."""
    a = ((words >> jnp.uint32(9)).astype(jnp.float32) + 0.5) * np.float32(2.0 ** -22)
    w = -jnp.log(a * (2.0 - a))
    central = w < 5.0
    t = jnp.where(central, w - 2.5, jnp.sqrt(w) - 3.0)
    c = [jnp.where(central, np.float32(p), np.float32(q)) for p, q in zip(_ERFINV_CENTRAL, _ERFINV_TAIL)]
    return (np.float32(np.sqrt(2.0)) * (a - 1.0)) * _estrin8(c, t)


def _normal(key, shape, dtype=jnp.float32) -> jax.Array:
    """Standard normal draws: the inverse CDF sqrt(2) erfinv(u) of :func:`uniform`'s u.

    float32 (and narrower): Giles' single-precision erfinv written out in fused array operations
    (faster than ``jax.scipy.special.erfinv`` on CPU, and more accurate: at most 6 float32 ulps
    from the exact inverse CDF at every one of the 2^23 points of the uniform grid, where
    ``log1p(-u^2)`` costs XLA's erfinv up to 91 ulps in the tails);
    float64: ``jax.scipy.special.erfinv`` of the float64 uniform."""
    dtype = jnp.dtype(dtype)
    if dtype == jnp.float64:
        return np.sqrt(2.0) * jax.scipy.special.erfinv(uniform(key, shape, dtype))
    if dtype not in (jnp.float32, jnp.float16, jnp.bfloat16):
        raise ValueError(f"normal: unsupported dtype {dtype}")
    return _normal32(bits(key, shape)).astype(dtype)


def _laplace(key, shape, dtype=jnp.float32) -> jax.Array:
    """Laplace draws with unit variance (scale 1/sqrt(2))."""
    v = uniform(key, shape, dtype)
    return (-jnp.sign(v) * jnp.log1p(-jnp.abs(v)) * np.sqrt(0.5)).astype(dtype)


def _uniform_law(key, shape, dtype=jnp.float32) -> jax.Array:
    """Uniform draws with unit variance, on (-sqrt 3, sqrt 3)."""
    return (np.sqrt(3.0) * uniform(key, shape, dtype)).astype(dtype)


# The public draws are jitted with the shape and dtype static: traced inside a caller's program,
# each (shape, dtype) is traced once per process and its jaxpr reused (the cipher and erfinv
# are some 150 operations; a diagnosis traces its samplers for ~10 sites x dozens of programs,
# and in a fresh process tracing them again cost ~2.6 s of the one-step checks alone). The
# nested program is inlined by XLA: the same operations, the same numbers.
_jit_draw = lambda f: jax.jit(f, static_argnames=("shape", "dtype"))  # noqa: E731
_normal_jit, _laplace_jit, _uniform_law_jit = (_jit_draw(f) for f in (_normal, _laplace, _uniform_law))


def normal(key, shape, dtype=jnp.float32) -> jax.Array:
    return _normal_jit(key, shape=tuple(int(d) for d in shape), dtype=jnp.dtype(dtype))


def laplace(key, shape, dtype=jnp.float32) -> jax.Array:
    return _laplace_jit(key, shape=tuple(int(d) for d in shape), dtype=jnp.dtype(dtype))


def uniform_law(key, shape, dtype=jnp.float32) -> jax.Array:
    return _uniform_law_jit(key, shape=tuple(int(d) for d in shape), dtype=jnp.dtype(dtype))


normal.__doc__, laplace.__doc__, uniform_law.__doc__ = _normal.__doc__, _laplace.__doc__, _uniform_law.__doc__


# ---- a block of rows of a draw ------------------------------------------------------------------
#: the float32 laws whose draws a block of rows can be made of alone (:func:`rows`)
ROW_LAWS = ("normal", "laplace", "uniform_law")


def _row_words(key, n: int, start, size: int):
    """Words ``start .. start + size - 1`` of the ``n``-word stream of ``key`` (uint32, (size,)):
    word w is the first output word of counter w below ceil(n/2), else the second output word of
    counter w - ceil(n/2) (the layout of :func:`bits`). Words past the stream's end are defined
    (a block's padding) but belong to no draw."""
    k0, k1 = key_words(key)
    half = jnp.uint32((n + 1) // 2)
    w = jnp.asarray(start, jnp.uint32) + jax.lax.iota(jnp.uint32, size)
    first = w < half
    y0, y1 = threefry2x32(k0, k1, jnp.where(first, w, w - half), jnp.zeros_like(w))
    return jnp.where(first, y0, y1)


def _uniform32(words):
    """The float32 uniform of :func:`uniform` on (-1, 1) from its words."""
    m = words >> jnp.uint32(9)
    return (m.astype(jnp.float32) + 0.5) * (2.0 ** -22) - 1.0


def _law_of_words(law: str, words):
    """A float32 law's draws from its words (:data:`ROW_LAWS`): the transforms of :func:`normal`,
    :func:`laplace` and :func:`uniform_law`, element by element."""
    if law == "normal":
        v = _normal32(words)
    else:
        u = _uniform32(words)
        v = -jnp.sign(u) * jnp.log1p(-jnp.abs(u)) * np.sqrt(0.5) if law == "laplace" else np.sqrt(3.0) * u
    return v.astype(jnp.float32)


@functools.partial(jax.jit, static_argnames=("law", "shape", "rows"))
def _rows(key, start, *, law: str, shape: tuple, rows: int):
    per_row = math.prod(shape[1:])
    words = _row_words(key, math.prod(shape), start * jnp.uint32(per_row), rows * per_row)
    return _law_of_words(law, words).reshape((rows,) + tuple(shape[1:]))


def rows_fit(shape, start: int, size: int) -> bool:
    """Whether :func:`rows` can make rows ``start .. start + size - 1`` of a draw of ``shape``:
    their word indices (padding included) below 2^32."""
    return math.prod(int(d) for d in shape[1:]) * (int(start) + int(size)) < 2 ** 32


def rows(law: str, key, shape, start: int, size: int) -> jax.Array:
    """Rows ``start .. start + size - 1`` (along the first axis) of the float32 draw
    ``normal(key, shape)`` (``law`` "normal"), ``laplace(...)`` or ``uniform_law(...)``, bit for
    bit, without drawing the rest: a large draw made a block of rows at a time. Rows past
    ``shape[0]`` are padding (defined, not part of the draw). ``start`` is traced: one compiled
    program per (law, shape, size) serves every block."""
    shape = tuple(int(d) for d in shape)
    if law not in ROW_LAWS:
        raise ValueError(f"rows: law {law!r} is not one of {ROW_LAWS}")
    if not rows_fit(shape, start, size):
        raise ValueError(f"rows: a draw of {shape} words exceeds the 2^32 word indices of a block")
    return _rows(key, np.uint32(start), law=law, shape=shape, rows=int(size))


# ---- a draw made by a program of a padded size ---------------------------------------------------
#: the largest draw (in words) :func:`padded_size` pads: above it a draw's run time outweighs its
#: program's compile time, and a program of its own shape wastes nothing
PADDED_MAX_WORDS = 2 ** 22


def padded_size(n: int) -> int | None:
    """The length of the program that makes an ``n``-word draw (:func:`tagged_flat`): the
    smallest of 1024, 1536, 2048, 3072, ... (2^e and 3 2^(e-1)) at least ``n``, so draws
    of different shapes share one compiled program (at most half of its words padding); None
    above :data:`PADDED_MAX_WORDS` (such a draw gets a program of its own shape)."""
    n = int(n)
    if n > PADDED_MAX_WORDS:
        return None
    size = 1024
    while size < n:
        size = size * 3 // 2 if size & (size - 1) == 0 else size // 3 * 4
    return size


@functools.partial(_xla.jit, static_argnames=("law", "size"))
def _tagged_flat(key, tag, n, *, law: str, size: int):
    words = _row_words(jax.random.fold_in(key, tag), n, jnp.uint32(0), size)
    return _law_of_words(law, words)


def tagged_flat(law: str, key, tag, n: int, size: int) -> jax.Array:
    """Words 0 .. ``size`` - 1 of the draw of ``n`` words of ``law`` (:data:`ROW_LAWS`) under
    ``fold_in(key, tag)``, as a flat float32 array: its first ``n`` values are
    ``normal(fold_in(key, tag), shape)`` (``laplace``, ``uniform_law``) of any ``shape`` of
    ``n`` elements, flattened, bit for bit (the rest is padding). ``n`` and ``tag`` are traced:
    one compiled program per (law, size) serves every draw that fits."""
    if law not in ROW_LAWS:
        raise ValueError(f"tagged_flat: law {law!r} is not one of {ROW_LAWS}")
    if not 0 < int(n) <= int(size) < 2 ** 32:
        raise ValueError(f"tagged_flat: {n} words do not fit a program of {size}")
    return _tagged_flat(key, np.uint32(tag), np.uint32(n), law=law, size=int(size))


# ---- jax.random.uniform's numbers, by a program of a padded length -------------------------------
def _jax_threefry_key(key) -> bool:
    """Whether ``jax.random.uniform`` draws ``key``'s bits from Threefry counters laid out by index
    (a Threefry key -- raw ``uint32`` under the default implementation, or typed -- with
    ``jax_threefry_partitionable``, JAX's default): its word i is then y0 ^ y1 of the cipher on
    the counter (0, i), whatever the shape."""
    if not jax.config.jax_threefry_partitionable:
        return False
    if jnp.issubdtype(getattr(key, "dtype", np.uint32), jax.dtypes.prng_key):
        return "threefry" in str(jax.random.key_impl(key))
    return str(jax.config.jax_default_prng_impl) == "threefry2x32" and tuple(np.shape(key)) == (2,)


def _jax_words(key, size: int):
    """Words 0 .. ``size`` - 1 of ``jax.random.bits(key, (n,))`` for any n >= size (the cipher on
    the counter (0, i), its two outputs xor-ed)."""
    k0, k1 = key_words(key)
    i = jax.lax.iota(jnp.uint32, size)
    y0, y1 = threefry2x32(k0, k1, jnp.zeros_like(i), i)
    return y0 ^ y1


def _mantissa01(key, size: int):
    """Words 0 .. ``size`` - 1 of ``jax.random.uniform``'s [0, 1) float32 values under ``key``."""
    one = np.float32(1.0)
    mantissa = (_jax_words(key, size) >> jnp.uint32(9)) | jnp.uint32(one.view(np.uint32))
    return jax.lax.bitcast_convert_type(mantissa, jnp.float32) - one


@functools.partial(_xla.jit, static_argnames=("size",))
def _uniform01_flat(key, *, size: int):
    return _mantissa01(key, size)


# compiled as JAX compiles its own samplers (no gift options): the same program, the same rounding
@functools.partial(jax.jit, static_argnames=("size",))
def _uniform_flat(key, minval, maxval, *, size: int):
    # jax.random.uniform's own operations on its [0, 1) values, in its order
    return jax.lax.max(minval, _mantissa01(key, size) * (maxval - minval) + minval)


@functools.partial(jax.jit, static_argnames=("size",))
def _normal_flat(key, *, size: int):
    # jax.random.normal: a uniform on (-1, 1) (its lower end the float after -1), times sqrt(2) erfinv
    lo, hi = np.nextafter(np.float32(-1.0), np.float32(0.0)), np.float32(1.0)
    u = jax.lax.max(lo, _mantissa01(key, size) * (hi - lo) + lo)
    return jax.lax.mul(np.float32(np.sqrt(2)), jax.lax.erf_inv(u))


def _eager() -> bool:
    """Whether no function is being traced (a draw made inside a trace belongs in its program:
    made apart, it would enter as a constant, and XLA rounds a fused sampler differently)."""
    clean = getattr(jax._src.core, "trace_state_clean", None)
    return bool(clean()) if clean is not None else False


def _as_jax_draws(key) -> bool:
    """Whether a padded program can make what ``jax.random`` makes from ``key`` here: outside a
    trace (a traced draw belongs in its program), without 64-bit mode (float64 values, int64
    permutations), a key whose bits are laid out by index (:func:`_jax_threefry_key`), on the CPU."""
    return (not isinstance(key, jax.core.Tracer) and _eager() and not jax.config.jax_enable_x64
            and _jax_threefry_key(key) and jax.default_backend() == "cpu")


def _padded_words(key, shape, dtype) -> int | None:
    """The padded length of a float32 draw of ``shape`` that a program of :func:`padded_size`
    words makes as JAX's own sampler would, or None where JAX must draw it (see
    :func:`_as_jax_draws`; another dtype, no words, too many)."""
    n = math.prod(shape)
    if n == 0 or jnp.dtype(jnp.float32 if dtype is None else dtype) != jnp.float32 or not _as_jax_draws(key):
        return None
    return padded_size(n)


def _reshaped(flat, shape) -> np.ndarray:
    return np.asarray(flat)[:math.prod(shape)].reshape(shape)


def uniform01(key, shape) -> np.ndarray:
    """``jax.random.uniform(key, shape)`` (float32 on [0, 1) without 64-bit mode; float64 with it,
    by ``jax.random.uniform`` itself) bit for bit, as a read-only numpy
    array, made by one compiled program per padded length (:func:`padded_size`) instead of one
    per shape, and without JAX's own Threefry lowering (whose compilation costs seconds per shape
    on a CPU). A traced call, a key or configuration whose bits are laid out otherwise, and draws
    above :data:`PADDED_MAX_WORDS` go to ``jax.random.uniform`` itself."""
    shape = tuple(int(d) for d in shape)
    size = _padded_words(key, shape, None)
    if size is None:
        return np.asarray(jax.random.uniform(key, shape))
    return _reshaped(_uniform01_flat(key, size=size), shape)


def uniform_like_jax(key, shape, dtype=None, minval=0.0, maxval=1.0):
    """``jax.random.uniform(key, shape, dtype, minval, maxval)`` bit for bit (a JAX array), for
    scalar bounds by one compiled program per padded length where :func:`uniform01` would use
    one; otherwise (array bounds, a traced key) by JAX itself."""
    shape = tuple(int(d) for d in shape)
    concrete = not any(isinstance(v, jax.core.Tracer) for v in (minval, maxval))
    size = _padded_words(key, shape, dtype) if concrete and np.ndim(minval) == 0 and np.ndim(maxval) == 0 else None
    if size is None:
        return jax.random.uniform(key, shape, dtype, minval, maxval)
    return jax.device_put(_reshaped(_uniform_flat(key, np.float32(minval), np.float32(maxval), size=size), shape))


def normal_like_jax(key, shape, dtype=None):
    """``jax.random.normal(key, shape, dtype)`` bit for bit (a JAX array), by one compiled program
    per padded length where :func:`uniform01` would use one; otherwise (a traced key) by JAX
    itself. (Not :func:`normal`, gift's own fused sampler, whose words are laid out differently.)"""
    shape = tuple(int(d) for d in shape)
    size = _padded_words(key, shape, dtype)
    if size is None:
        return jax.random.normal(key, shape, dtype)
    return jax.device_put(_reshaped(_normal_flat(key, size=size), shape))


_bits_flat = jax.jit(_jax_words, static_argnames=("size",))


def _rounds(n: int) -> int:
    """The sorting rounds of ``jax.random.permutation`` of ``n`` items."""
    return int(np.ceil(3 * np.log(max(1, n)) / np.log(np.iinfo(np.uint32).max)))


def permutation(key, n: int) -> np.ndarray:
    """``jax.random.permutation(key, n)`` for an integer ``n``, bit for bit (an int32 numpy array).

    JAX shuffles ``arange(n)`` in ``ceil(3 ln n / ln(2^32 - 1))`` rounds, each a stable sort of
    the current order by 32 fresh random bits per position (the bits of ``split(key)[1]``, the
    next round keyed by ``split(key)[0]``); here each round's bits come from a program of a padded
    length (:func:`padded_size`) and the stable sort is numpy's, so no program is compiled per
    ``n``. Elsewhere (:func:`_as_jax_draws`: a trace, 64-bit mode, another key) JAX shuffles itself."""
    n = int(n)
    size = padded_size(n) if n > 0 else None
    if size is None or not _as_jax_draws(key):
        return np.asarray(jax.random.permutation(key, n))
    x = np.arange(n, dtype=np.int32)
    for _ in range(_rounds(n)):
        key, subkey = jax.random.split(key)
        bits = np.asarray(_bits_flat(subkey, size=size))[:n]
        x = x[np.argsort(bits, kind="stable")]
    return x


@functools.partial(jax.jit, static_argnames=("rows", "r", "rounds"))
def _split_shuffle_bits(key, *, rows: int, r: int, rounds: int):
    # split(key, rows)[i] is the cipher of the counter (0, i); split(k) is [cipher_k(0, 0), cipher_k(0, 1)]:
    # each round sorts by the bits of the second and hands the first to the next round
    k0, k1 = key_words(key)
    i = jax.lax.iota(jnp.uint32, rows)
    a0, a1 = threefry2x32(k0, k1, jnp.zeros_like(i), i)
    j = jax.lax.iota(jnp.uint32, r)[None, :]
    zero, one = jnp.uint32(0), jnp.uint32(1)
    out = []
    for _ in range(rounds):
        s0, s1 = threefry2x32(a0, a1, zero, one)
        a0, a1 = threefry2x32(a0, a1, zero, zero)
        y0, y1 = threefry2x32(s0[:, None], s1[:, None], jnp.zeros_like(j), j)
        out.append(y0 ^ y1)
    return jnp.stack(out) if out else jnp.zeros((0, rows, r), jnp.uint32)


def split_permutations(key, n: int, r: int) -> np.ndarray:
    """``vmap(lambda k: jax.random.permutation(k, r))(jax.random.split(key, n))`` bit for bit, an
    (n, r) int32 numpy array: each round's bits from one program per (padded n, r, rounds), the
    stable sorts numpy's (see :func:`permutation`); elsewhere (:func:`_as_jax_draws`) by JAX."""
    n, r = int(n), int(r)
    rows = padded_size(n) if n > 0 else None
    if rows is None or rows * r * max(_rounds(r), 1) > PADDED_MAX_WORDS or not _as_jax_draws(key):
        return np.asarray(jax.vmap(lambda k: jax.random.permutation(k, r))(jax.random.split(key, n)))
    x = np.broadcast_to(np.arange(r, dtype=np.int32), (n, r))
    for bits in np.asarray(_split_shuffle_bits(key, rows=rows, r=r, rounds=_rounds(r)))[:, :n]:
        x = np.take_along_axis(x, np.argsort(bits, axis=1, kind="stable"), axis=1)
    return np.ascontiguousarray(x)
