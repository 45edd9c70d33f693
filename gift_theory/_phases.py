"""Wall time and JAX compilation time per named phase of a computation (for profiles).

``with PhaseClock() as clock:`` activates a clock for the current context; library code marks
its phases with ``with phase("referee"):`` (a no-op when no clock is active, so marking costs
nothing in ordinary use). Phases nest: a phase opened inside ``"method"`` is recorded as
``"method/direction"``. Besides wall seconds, every phase records the seconds JAX spent
tracing, lowering and compiling inside it and how many programs it compiled, read from
``jax.monitoring`` events, so a profile separates compilation from arithmetic.

Phases are timed on the host: a phase that only dispatches asynchronous work is charged
when a later phase blocks on it; every phase marked in gift ends by reading its numbers back
(``float(...)``, ``np.asarray``), which blocks.
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
import time
from collections import Counter

_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
_lock = threading.Lock()
_totals = {"seconds": 0.0, "compiles": 0}
_by_function: Counter = Counter()
_seconds_by_function: Counter = Counter()
_listening = False
_current: contextvars.ContextVar = contextvars.ContextVar("gift_phase_clock", default=None)
_path: contextvars.ContextVar = contextvars.ContextVar("gift_phase_path", default=())


def _on_duration(event: str, seconds: float, **kw) -> None:
    if event not in _COMPILE_EVENTS:
        return
    with _lock:
        _totals["seconds"] += seconds
        _seconds_by_function[str(kw.get("fun_name", "?")).removeprefix("jit(").removesuffix(")")] += seconds
        if event == "/jax/core/compile/backend_compile_duration":
            _totals["compiles"] += 1
            _by_function[str(kw.get("fun_name", "?")).removeprefix("jit(").removesuffix(")")] += 1


def listen() -> None:
    """Start counting JAX compilations in this process (idempotent)."""
    global _listening
    if _listening:
        return
    from jax import monitoring

    monitoring.register_event_duration_secs_listener(_on_duration)
    _listening = True


def compile_totals() -> tuple[float, int]:
    """(seconds spent tracing/lowering/compiling, number of programs compiled) since :func:`listen`."""
    with _lock:
        return _totals["seconds"], _totals["compiles"]


def compiled_functions() -> dict[str, dict]:
    """Per function name since :func:`listen`: programs compiled and seconds spent compiling them."""
    with _lock:
        return {k: {"programs": _by_function[k], "seconds": _seconds_by_function[k]}
                for k in sorted(_seconds_by_function, key=lambda k: -_seconds_by_function[k])}


class PhaseClock:
    """Accumulates ``{phase: {"seconds", "compile_seconds", "compiles", "calls"}}``."""

    def __init__(self):
        self.phases: dict[str, dict] = {}
        self._token = None

    def __enter__(self) -> "PhaseClock":
        listen()
        self._token = _current.set(self)
        return self

    def __exit__(self, *exc) -> None:
        _current.reset(self._token)

    def add(self, name: str, seconds: float, compile_seconds: float, compiles: int) -> None:
        p = self.phases.setdefault(name, {"seconds": 0.0, "compile_seconds": 0.0, "compiles": 0, "calls": 0})
        p["seconds"] += seconds
        p["compile_seconds"] += compile_seconds
        p["compiles"] += compiles
        p["calls"] += 1


@contextlib.contextmanager
def phase(name: str):
    """Time the block as phase ``name`` of the active :class:`PhaseClock` (if any)."""
    clock = _current.get()
    if clock is None:
        yield
        return
    path = _path.get() + (name,)
    token = _path.set(path)
    c0, n0 = compile_totals()
    t0 = time.perf_counter()
    try:
        yield
    finally:
        seconds = time.perf_counter() - t0
        c1, n1 = compile_totals()
        _path.reset(token)
        clock.add("/".join(path), seconds, c1 - c0, n1 - n0)
