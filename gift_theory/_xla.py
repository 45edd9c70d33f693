"""``jit`` with the XLA:CPU options gift's dense kernels want, applied only where XLA accepts them.

XLA:CPU (jaxlib 0.10) hands every matrix product, reduction and elementwise chain it can to
its YNNPACK library ("YNN fusions"). For the products of a dense network that costs speed:
on a 2-core AVX-512 machine a 8192 x 784 by 784 x 500 float32 product runs at about 0.75 of
numpy's rate through YNNPACK and at numpy's rate through XLA's own dot emitter, while
YNNPACK's row reductions (the score statistics' sums of squares) are ~9x faster than XLA's.
So the estimators compile with ``xla_cpu_experimental_ynn_fusion_type`` restricted to
reductions (measured on the paper's deeper net, K1 = 1024 x K2 = 8: the score_paper kernel
0.22 s -> 0.18 s, the pathwise one 0.40 s -> 0.34 s; ``gift bench`` reports the result).

XLA:CPU also vectorises its loops 256 bits wide by default, even on AVX-512 machines, and
its loops run one vector at a time: the noise sampler (Threefry's 20 dependent rounds, the
erfinv polynomial) is latency-bound, so ``xla_cpu_prefer_vector_width=512`` draws twice the
lanes per step (the 25 M draws of that estimate: 0.066 s -> 0.039 s, bit for bit the same
numbers). Machines without AVX-512 keep their widest vectors.

The option is an experimental XLA flag: :func:`jit` probes once, on first use, whether the
installed XLA knows it, and compiles without it otherwise -- same numbers up to float
rounding, only slower. ``GIFT_XLA_DEFAULTS=1`` in the environment turns the options off.

A program marked *run-bound* (``jit(..., run_bound=True)``: one program run many times over
large arrays, such as the lab's Gaussian smoothing of tanh) also compiles at XLA's default
backend optimisation level (:data:`RUN_BOUND_LEVEL`) where ``XLA_FLAGS`` lowers it for every
program (the test run does, to compile its thousands of small programs cheaply). Its run time
outweighs its compile time: at level 0 LLVM leaves its loops unvectorised (the smoothing's
wide rule ran 4x slower). Where no flag lowers the level -- any run of ``gift`` -- it compiles
as every other program does, so the mark changes no number there.

Compiled programs are also kept on disk (JAX's persistent compilation cache), so a new
process -- a Dask worker of a sweep, the next ``gift`` command -- loads the programs an
earlier one compiled instead of compiling them again: :func:`use_compilation_cache`, called
by the ``gift`` command and the sweeps' workers (importing gift_theory does not; a script
calls ``gift_theory.use_compilation_cache()`` itself), points JAX at ``$GIFT_COMPILATION_CACHE`` or, by default, the ``xla``
folder of gift's cache (``$GIFT_CACHE_DIR`` or ``~/.cache/gift``), and keeps every program
(:data:`CACHE_MIN_COMPILE_SECONDS`). ``GIFT_COMPILATION_CACHE=off``
turns it off; a folder the user already gave JAX (``jax_compilation_cache_dir``) is kept.
Processes may share the folder (the workers of a sweep): JAX writes an entry in one piece and
reads it back whole; without the ``filelock`` package it takes no lock, so a process reading
an entry at the very moment another writes the same one may see it truncated -- JAX then
warns and compiles the program itself (the compressed entry fails to decompress: a lost
shortcut, not a wrong program).
"""

from __future__ import annotations

import functools
import os
import re

import jax
import jax.numpy as jnp

CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": "LIBRARY_FUSION_TYPE_REDUCE",
               "xla_cpu_prefer_vector_width": 512}


#: programs that compile faster than this are not written to the disk cache. Every program is
#: kept: a diagnose compiles some 240, most of them small (one per physics structure and
#: shape), and reading one back takes ~8 ms against ~27 ms to compile it. Measured on 2 cores
#: (``python -m studies.calibrate time --taps``, a fresh process): 17.5-20 s with a threshold of
#: 0.2 s (166 of the 244 programs compiled again), 14.5-15 s with none.
CACHE_MIN_COMPILE_SECONDS = 0.0
_OFF = ("0", "off", "none", "false", "no")  # values of GIFT_COMPILATION_CACHE that turn it off


def compilation_cache_dir() -> str | None:
    """The persistent cache folder gift uses: ``$GIFT_COMPILATION_CACHE``, else ``<gift cache>/xla``;
    None when the variable says off."""
    env = os.environ.get("GIFT_COMPILATION_CACHE", "").strip()
    if env.lower() in _OFF:
        return None
    if env:
        return env
    from ._cachedir import cache_dir

    return os.path.join(cache_dir(), "xla")


def use_compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at :func:`compilation_cache_dir` (unless the
    user set one already); returns the folder in use, or None. Sets configuration only: no
    backend is started."""
    current = jax.config.jax_compilation_cache_dir
    if current:
        return current
    folder = compilation_cache_dir()
    if folder is None:
        return None
    from ._cachedir import unwritable, writable

    why = writable(folder)
    if why is not None:  # JAX would warn on every program it fails to keep: one line, then none kept
        unwritable(folder, why, "compiled programs")
        return None
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_SECONDS)
    return folder


#: XLA's default backend (LLVM) optimisation level: a run-bound program compiles at least at it
RUN_BOUND_LEVEL = 2


@functools.lru_cache(maxsize=None)
def compiler_options(run_bound: bool = False, cpu: bool = True) -> tuple:
    """The options this JAX/XLA accepts, as sorted (name, value) pairs (empty off CPU):
    :data:`CPU_OPTIONS` (``cpu``) and, ``run_bound``, :data:`RUN_BOUND_LEVEL` where
    ``XLA_FLAGS`` sets a lower level."""
    if os.environ.get("GIFT_XLA_DEFAULTS", "") not in ("", "0"):
        return ()
    opts = dict(_accepted(tuple(sorted(CPU_OPTIONS.items()))) if cpu else ())
    level = _flag_level() if run_bound else None
    if level is not None and level < RUN_BOUND_LEVEL:
        opts.update(_accepted((("xla_backend_optimization_level", RUN_BOUND_LEVEL),)))
    return tuple(sorted(opts.items()))


def _flag_level() -> int | None:
    """The backend optimisation level ``XLA_FLAGS`` sets (its last mention), or None."""
    found = re.findall(r"--xla_backend_optimization_level=(\d+)", os.environ.get("XLA_FLAGS", ""))
    return int(found[-1]) if found else None


@functools.lru_cache(maxsize=None)
def _accepted(options: tuple) -> tuple:
    """``options`` if this JAX/XLA compiles a program with them on the CPU, else ()."""
    try:
        if jax.default_backend() != "cpu":
            return ()
        jax.jit(lambda a: a + 1, compiler_options=dict(options)).lower(jnp.zeros(2)).compile()
    except Exception:  # an older jax without compiler_options, or an XLA without the flag
        return ()
    return options


def jit(fun=None, *, run_bound: bool = False, cpu_options: bool = True, **jit_kwargs):
    """``jax.jit(fun, **jit_kwargs)`` plus :data:`CPU_OPTIONS` where accepted (unless
    ``cpu_options`` is false: XLA's own choices); usable as ``@jit`` or
    ``@partial(jit, static_argnames=...)``. ``run_bound``: the program compiles at XLA's
    default optimisation level even where ``XLA_FLAGS`` lowers it (see the module). The options
    are looked up on the first call, so importing gift does not start a backend."""
    if fun is None:
        return functools.partial(jit, run_bound=run_bound, cpu_options=cpu_options, **jit_kwargs)
    compiled = {}

    @functools.wraps(fun)
    def call(*args, **kwargs):
        opts = compiler_options(run_bound, cpu_options)
        f = compiled.get(opts)
        if f is None:
            f = compiled[opts] = jax.jit(fun, **jit_kwargs, **({"compiler_options": dict(opts)} if opts else {}))
        return f(*args, **kwargs)

    return call
