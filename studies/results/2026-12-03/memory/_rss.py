"""The peak RSS of one stage of work: memory freed before it is given back first (malloc_trim),
then the process's RSS is sampled every 0.05 s while the stage runs. Shared by loc.py and cand.py."""
import ctypes, threading, time

libc = ctypes.CDLL("libc.so.6")
peak = [0.0]


def rss():
    for l in open("/proc/self/status"):
        if l.startswith("VmRSS"):
            return int(l.split()[1]) / 1e6


def _mon():
    while True:
        peak[0] = max(peak[0], rss())
        time.sleep(0.05)


threading.Thread(target=_mon, daemon=True).start()


def stage(name, f):
    libc.malloc_trim(0); time.sleep(0.1); peak[0] = rss(); before = peak[0]; t0 = time.time()
    out = f(); time.sleep(0.1)
    print(f"{name:22s} before {before:.2f} peak {peak[0]:.2f} after {rss():.2f} GB ({time.time()-t0:.1f} s)", flush=True)
    return out
