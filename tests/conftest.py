"""Shared test configuration.

* ``x64``: a fixture that runs a test in float64 (tests about mathematics use it).
* The weight cache goes to a temporary folder so tests never touch the user's cache.
* hypothesis: a profile with a deadline that tolerates JAX compilation.
* XLA compiles at backend optimisation level 0 (:func:`_xla_flags`: the suite is compile-bound).
* numpy's global generator (tests that draw a fresh seed with ``np.random.randint`` each run)
  is seeded per test from one run seed, ``GIFT_TEST_SEED`` (random unless set), printed in the
  header and under a failing test: ``GIFT_TEST_SEED=N python -m pytest ...`` replays a run.
"""

import os
import random
import shutil
import tempfile
import zlib

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("gift", deadline=None, max_examples=25,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile("gift")


_MADE = []


def pytest_configure(config):
    # set once by the controller; xdist workers inherit it
    os.environ.setdefault("GIFT_TEST_SEED", str(random.SystemRandom().randrange(2 ** 31)))
    if "GIFT_CACHE_DIR" not in os.environ:
        _MADE.append(tempfile.mkdtemp(prefix="gift-test-cache-"))
        os.environ["GIFT_CACHE_DIR"] = _MADE[-1]
    os.environ.setdefault("MPLBACKEND", "agg")
    _xla_flags()
    _compilation_cache()


#: XLA's backend (LLVM) optimisation level for the test run; XLA's default is 2
TEST_XLA_OPT_LEVEL = 0


def _xla_flags():
    """Compile the test run's programs at LLVM optimisation level 0 instead of XLA's default 2
    (``--xla_backend_optimization_level``), in this process and every command a test starts.

    The suite is compile-bound: it builds thousands of small programs, one per physics structure
    and chip shape, and runs each a few times, so the compiler's time outweighs what its
    optimisations save. Measured on 2 cores, one process each, CPU seconds: the nine hidden-effect
    diagnoses of tests/lab/test_diagnose.py 98 at level 1, 85 at level 0; tests/finetune/test_memo.py,
    test_referee.py and tests/estimators together (trainings and Monte Carlo: run-time heavy) 99 at
    level 1, 85 at level 0 (level 2 was slower than level 1 over the whole suite). The programs are
    the same; their float rounding may differ in the last bits (no fast-math at any level), which no
    test may depend on. ``GIFT_TEST_XLA_DEFAULTS=1`` runs it at XLA's defaults; a level the user
    put in ``XLA_FLAGS`` is kept. Must run before the first computation (the flags are
    read when the backend starts)."""
    if os.environ.get("GIFT_TEST_XLA_DEFAULTS", "") not in ("", "0"):
        return
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_backend_optimization_level={TEST_XLA_OPT_LEVEL}".strip()


def _compilation_cache():
    """One persistent compilation cache per test run, in a fresh temporary folder, shared by the
    xdist workers and every command a test starts (a program one process compiled, the others
    load: the same chips and shapes recur across tests). ``GIFT_COMPILATION_CACHE`` set by the
    user is kept.

    JAX writes an entry without a lock (it locks only a cache with a size limit, and then scans
    the whole folder on every write: quadratic in the entries, measured slower than no cache
    over this suite's ~7000 programs). A process reading an entry at the moment another writes
    it can see it truncated: JAX then warns and compiles the program itself -- the compressed
    entry fails to decompress, so a truncated entry is never a wrong program. That warning
    alone is not an error here (``pyproject.toml``'s filterwarnings)."""
    if "GIFT_COMPILATION_CACHE" not in os.environ:
        _MADE.append(tempfile.mkdtemp(prefix="gift-test-xla-"))
        os.environ["GIFT_COMPILATION_CACHE"] = _MADE[-1]
    import gift_theory as gt

    gt.use_compilation_cache()


def pytest_unconfigure(config):
    """Remove the temporary folders this process made (the weight cache: each xdist worker makes
    its own; the compilation cache: the controller's, which the workers inherit)."""
    for folder in _MADE:
        shutil.rmtree(folder, ignore_errors=True)
        if os.environ.get("GIFT_CACHE_DIR") == folder:
            del os.environ["GIFT_CACHE_DIR"]


def pytest_report_header(config):
    return f"GIFT_TEST_SEED={os.environ['GIFT_TEST_SEED']} (set it to replay this run's random seeds)"


@pytest.fixture(autouse=True)
def _seeded_numpy(request):
    """numpy's global generator from the run seed and the test's id (order-independent)."""
    seed = int(os.environ["GIFT_TEST_SEED"])
    np.random.seed((seed + zlib.crc32(request.node.nodeid.encode())) % 2 ** 32)
    request.node.add_report_section("call", "seed", f"GIFT_TEST_SEED={seed}")
    yield


@pytest.fixture
def x64():
    """Run the test body with 64-bit floats in JAX."""
    with jax.enable_x64(True):
        yield
