"""Shared test configuration.

* ``x64``: a fixture that runs a test in float64 (tests about mathematics use it).
* The weight cache goes to a temporary folder so tests never touch the user's cache.
* hypothesis: a profile with a deadline that tolerates JAX compilation.
"""

import os
import shutil
import tempfile

import jax
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("gift", deadline=None, max_examples=25,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile("gift")


_MADE = []


def pytest_configure(config):
    if "GIFT_CACHE_DIR" not in os.environ:
        _MADE.append(tempfile.mkdtemp(prefix="gift-test-cache-"))
        os.environ["GIFT_CACHE_DIR"] = _MADE[-1]
    os.environ.setdefault("MPLBACKEND", "agg")


def pytest_unconfigure(config):
    """Remove the temporary weight cache this process made (each xdist worker makes its own)."""
    for folder in _MADE:
        shutil.rmtree(folder, ignore_errors=True)
        if os.environ.get("GIFT_CACHE_DIR") == folder:
            del os.environ["GIFT_CACHE_DIR"]


@pytest.fixture
def x64():
    """Run the test body with 64-bit floats in JAX."""
    with jax.enable_x64(True):
        yield
