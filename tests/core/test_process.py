"""The process-level memory calls: freed memory given back to the system (glibc), nothing else
changed. Run in a fresh interpreter, so the test's own allocations are the only ones."""

import subprocess
import sys

import pytest

_CHILD = r"""
import sys
import numpy as np
from gift_theory._process import _glibc, release_freed_memory

if _glibc() is None:
    print("no-glibc")
    sys.exit(0)

def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024

# a 24 MiB array freed raises glibc's mmap threshold to its size: arrays of a few MiB then come
# from the heap, as numpy's per-input temporaries of a large campaign do
big = np.ones(3 << 20)
del big
arrays = [np.ones(1 << 18) for _ in range(240)]  # 240 x 2 MiB, touched
for i in range(0, len(arrays) - 1, 2):  # every other one freed: holes the heap's top cannot give back
    arrays[i] = None
before = rss_mb()
release_freed_memory()
after = rss_mb()
print(f"{before:.1f} {after:.1f}")
"""


@pytest.mark.slow
def test_freed_memory_goes_back_to_the_system():
    proc = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = proc.stdout.split()
    if out == ["no-glibc"]:
        pytest.skip("not glibc: release_freed_memory is a no-op")
    before, after = (float(v) for v in out)
    # 120 holes of 2 MiB were free: most of their 240 MiB leaves the process
    assert before - after > 150, (before, after)
