"""Shared test configuration.

* ``x64``: a fixture that runs a test in float64 (tests about mathematics use it).
* The weight cache goes to a temporary folder so tests never touch the user's cache.
* hypothesis: a profile with a deadline that tolerates JAX compilation.
* XLA compiles at backend optimisation level 0 with its classic emitters (:func:`_xla_flags`:
  the suite is compile-bound); the programs gift marks run-bound keep XLA's default level
  (``gift_theory._xla.jit``).
* Each xdist worker (and every command it starts) runs OpenBLAS on one thread
  (``OPENBLAS_NUM_THREADS=1`` unless set) and draws figures without a helper process
  (``GIFT_FIGURE_PROCESSES=1``): two workers share two cores, and a worker's BLAS threads or
  drawing helper would only wait on the other worker (:func:`_one_core_per_worker`).
* numpy's global generator (tests that draw a fresh seed with ``np.random.randint`` each run)
  is seeded per test from one run seed, ``GIFT_TEST_SEED`` (random unless set), printed in the
  header and under a failing test: ``GIFT_TEST_SEED=N python -m pytest ...`` replays a run.
"""

import os
import random
import shutil
import subprocess
import sys
import tempfile
import zlib


def _one_core_per_worker():
    """One OpenBLAS thread and no drawing helper in an xdist worker: the run's workers already
    fill the cores, so a worker's BLAS threads would only spin against the other worker
    (test_diagnose.py on 2 cores, two workers: about a tenth less wall time), and a helper
    process's start-up would be paid for nothing. Set before numpy loads BLAS; a value the user
    set is kept, and a run without workers is left alone."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
        os.environ.setdefault("GIFT_FIGURE_PROCESSES", "1")


_one_core_per_worker()

import jax  # noqa: E402  (after the BLAS setting: numpy reads it when it loads)
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

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

#: XLA:CPU options the test run adds where the installed XLA knows them (name -> value)
TEST_XLA_OPTIONS = {"xla_cpu_use_fusion_emitters": "false"}


def _xla_flags():
    """Compile the test run's programs cheaply, in this process and every command a test starts:
    LLVM optimisation level 0 instead of XLA's default 2 (``--xla_backend_optimization_level``)
    and XLA:CPU's classic elemental emitters instead of its MLIR fusion emitters
    (:data:`TEST_XLA_OPTIONS`).

    The suite is compile-bound: it builds thousands of small programs, one per physics structure
    and chip shape, and runs each a few times, so the compiler's time outweighs what its
    optimisations save. Measured on 2 cores, one process each, CPU seconds: the nine hidden-effect
    diagnoses of tests/lab/test_diagnose.py 98 at level 1, 85 at level 0; tests/finetune/test_memo.py,
    test_referee.py and tests/estimators together (trainings and Monte Carlo: run-time heavy) 99 at
    level 1, 85 at level 0 (level 2 was slower than level 1 over the whole suite). One diagnosis
    of a 6-12-6-4 chip in a fresh process with no compilation cache: 18.4 CPU s with the fusion
    emitters, 12.0 without (XLA's compile time of its 93 programs halves). The programs compute
    the same functions; their float rounding may differ in the last bits (no fast-math anywhere),
    which no test may depend on. ``GIFT_TEST_XLA_DEFAULTS=1`` runs the suite at XLA's defaults; a
    flag the user put in ``XLA_FLAGS`` is kept. An option this XLA does not know is left out
    (XLA aborts on an unknown flag: :func:`_known_xla_flags` asks a child process once). Must run
    before the first computation (the flags are read when the backend starts)."""
    if os.environ.get("GIFT_TEST_XLA_DEFAULTS", "") not in ("", "0"):
        return
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" not in flags:
        flags = f"{flags} --xla_backend_optimization_level={TEST_XLA_OPT_LEVEL}"
    wanted = [f"--{k}={v}" for k, v in TEST_XLA_OPTIONS.items() if k not in flags]
    os.environ["XLA_FLAGS"] = " ".join([flags.strip()] + _known_xla_flags(flags.strip(), wanted)).strip()


def _known_xla_flags(base: str, wanted: list) -> list:
    """The flags of ``wanted`` a JAX backend starts with (beside ``base``): one child process
    per run (xdist workers inherit the result through ``XLA_FLAGS``)."""
    if not wanted:
        return []
    probe = [sys.executable, "-c", "import jax.numpy as jnp; jnp.zeros(1).block_until_ready()"]
    env = dict(os.environ, XLA_FLAGS=" ".join([base] + wanted).strip(), JAX_PLATFORMS="cpu")
    ok = subprocess.run(probe, env=env, capture_output=True, timeout=300).returncode == 0
    return wanted if ok else []


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
