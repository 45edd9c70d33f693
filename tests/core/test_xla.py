"""gift's ``jit``: a run-bound program compiles at XLA's default optimisation level where
``XLA_FLAGS`` lowers it, and exactly as before where nothing does.

Private on purpose (``gift_theory._xla``): the options a program compiles with are not part of
the public API, and the contract is subtle -- a run-bound mark must change no number in a run of
``gift`` (no flag), only the speed of a run that lowers the level (the test run)."""

import os
import subprocess
import sys

from gift_theory import _xla

_PROBE = r"""
import json, sys
import numpy as np
import jax
from gift_theory import _xla
from gift_theory.lab import _smoothing as sm

z = np.linspace(-3.0, 3.0, 3 * sm.WIDE_CHUNK // 4)  # compiled: above a quarter of a chunk
sd = np.linspace(0.6, 4.0, z.size)
m, g = sm._tanh_wide(z, sd)
mn, gn = sm._tanh_wide_numpy(z, sd)
# the same rule by plain jax.jit, as the program compiled before it was marked run-bound
with sm._x64()(True):
    zp = np.concatenate([z, np.zeros(sm.WIDE_CHUNK - z.size)])
    sp = np.concatenate([sd, np.ones(sm.WIDE_CHUNK - z.size)])
    mp, gp = (np.asarray(v)[:z.size] for v in jax.jit(sm._wide_rule())(zp, sp))
print(json.dumps({
    "options": [list(o) for o in _xla.compiler_options(True, False)],
    "plain": [list(o) for o in _xla.compiler_options(False, False)],
    "same_as_plain_jit": bool(np.array_equal(m, mp) and np.array_equal(g, gp)),
    "err_vs_numpy": float(max(np.max(np.abs(m - mn)), np.max(np.abs(g - gn)))),
}))
"""


def _probe(xla_flags):
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "GIFT_XLA_DEFAULTS")}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    proc = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    import json

    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_run_bound_program_compiles_as_before_where_no_flag_lowers_the_level():
    out = _probe(None)
    assert out["options"] == [] and out["plain"] == []
    # the smoothing's wide rule (run-bound) gives plain jax.jit's numbers bit for bit
    assert out["same_as_plain_jit"]
    assert out["err_vs_numpy"] < 1e-12


def test_a_run_bound_program_compiles_at_xla_s_default_level_where_a_flag_lowers_it():
    out = _probe("--xla_backend_optimization_level=0")
    assert out["options"] == [["xla_backend_optimization_level", _xla.RUN_BOUND_LEVEL]]
    assert out["plain"] == []  # a program not marked keeps the flag's level
    assert out["err_vs_numpy"] < 1e-12  # the same rule, its rounding aside
    # a level at or above the default is left alone
    assert _probe("--xla_backend_optimization_level=3")["options"] == []


def test_the_level_the_flags_set_is_their_last_mention(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_backend_optimization_level=2 --foo=1 --xla_backend_optimization_level=0")
    assert _xla._flag_level() == 0
    monkeypatch.setenv("XLA_FLAGS", "--foo=1")
    assert _xla._flag_level() is None
    monkeypatch.delenv("XLA_FLAGS")
    assert _xla._flag_level() is None
