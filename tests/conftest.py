"""Shared test configuration.

* ``x64``: a fixture that runs a test in float64 (tests about mathematics use it).
* The weight cache goes to a temporary folder so tests never touch the user's cache.
* hypothesis: a profile with a deadline that tolerates JAX compilation.
"""

import os
import tempfile

import jax
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("gift", deadline=None, max_examples=25,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile("gift")


def pytest_configure(config):
    os.environ.setdefault("GIFT_CACHE_DIR", tempfile.mkdtemp(prefix="gift-test-cache-"))
    os.environ.setdefault("MPLBACKEND", "agg")


@pytest.fixture
def x64():
    """Run the test body with 64-bit floats in JAX."""
    with jax.enable_x64(True):
        yield
