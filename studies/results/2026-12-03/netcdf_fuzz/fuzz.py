"""Corrupt one small netCDF measurement N times and read each through gift's loader in a child
process, with a time limit per file: counts of loaded / bad input / crash / hang.

    python fuzz.py N SEED0 OUT.jsonl [FOLDER]       # PYTHONPATH=<the code tree>

The file is tests/lab/test_file_rules.py's ``meas`` (3-4-2, 8 inputs x 8 shots, taps), written by
``save_netcdf``; corruptions as that file's property test makes them (1-8 bit flips with weight 5,
a truncation, 1-40 bytes of garbage inserted, each with weight 1). A file that takes the child more
than 30 s is a hang: the child is killed and started again, and the file is kept as hangSEED.nc.
"""
import collections
import json
import os
import random
import select
import subprocess
import sys
import tempfile

CHILD = r'''
import sys, warnings
warnings.simplefilter("ignore")
from gift_theory import GiftInputError
from gift_theory.lab._io import load_netcdf
weights = sys.argv[1]
for line in sys.stdin:
    try:
        load_netcdf(line.strip(), weights=weights)
        r = "ok"
    except GiftInputError as e:
        r = "bad " + str(e)[:200].replace("\n", " ")
    except BaseException as e:
        r = "CRASH " + type(e).__name__ + " " + str(e)[:200].replace("\n", " ")
    print(r, flush=True)
'''


def make(folder):
    import jax
    import numpy as np

    import gift_theory as gt
    from gift_theory.lab import save_netcdf, simulate_measurement
    params = gt.init_params(jax.random.PRNGKey(0), gt.Architecture((3, 4, 2)))
    x = np.asarray(jax.random.uniform(jax.random.PRNGKey(1), (8, 3)), np.float64)
    m = simulate_measurement(jax.random.PRNGKey(2), params, x, gt.Physics.create(s=0.1), shots=8, taps=True)
    save_netcdf(os.path.join(folder, "good.nc"), m)
    np.savez(os.path.join(folder, "weights.npz"),
             **{k: v for k, v in m.arrays().items() if k[:1] in "Wb" or k == "activation"})


def corrupt(data, rnd, how):
    if how == "truncate":
        return data[: rnd.randrange(len(data))]
    if how == "flip":
        b = bytearray(data)
        for _ in range(rnd.randint(1, 8)):
            i = rnd.randrange(len(b))
            b[i] ^= 1 << rnd.randrange(8)
        return bytes(b)
    i = rnd.randrange(len(data))
    return data[:i] + bytes(rnd.randrange(256) for _ in range(rnd.randint(1, 40))) + data[i:]


def main():
    n, seed0, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    folder = sys.argv[4] if len(sys.argv) > 4 else tempfile.mkdtemp(prefix="ncfuzz-")
    make(folder)
    good = open(os.path.join(folder, "good.nc"), "rb").read()
    start = lambda: subprocess.Popen([sys.executable, "-c", CHILD, os.path.join(folder, "weights.npz")],  # noqa: E731
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
    child, counts = start(), collections.Counter()
    with open(out, "w") as fo:
        for k in range(n):
            seed = seed0 + k
            rnd = random.Random(seed)
            how = rnd.choice(["flip"] * 5 + ["truncate", "garbage"])
            path = os.path.join(folder, "case.nc")
            with open(path, "wb") as f:
                f.write(corrupt(good, rnd, how))
            child.stdin.write(path + "\n")
            child.stdin.flush()
            if select.select([child.stdout], [], [], 30)[0]:
                res = child.stdout.readline().strip()
            else:
                res = "HANG"
                child.kill()
                child.wait()
                child = start()
                os.replace(path, os.path.join(folder, f"hang{seed}.nc"))
            counts[res.split()[0]] += 1
            fo.write(json.dumps({"seed": seed, "how": how, "result": res}) + "\n")
            fo.flush()
            if k % 100 == 0:
                print(k, dict(counts), file=sys.stderr, flush=True)
    print(json.dumps(dict(counts)))


if __name__ == "__main__":
    main()
