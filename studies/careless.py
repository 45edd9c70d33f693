"""Issue 45's cases: what a careless or unlucky user does to gift, each as one command line.

    python -m studies.careless run OUT.jsonl [--code DIR] [--only NAME,...] [--skip-slow]
    python -m studies.careless table BEFORE.jsonl AFTER.jsonl

``run`` makes each case's files in a fresh folder, runs the ``gift`` command of the code tree
``DIR`` (default: the one this module belongs to; ``PYTHONPATH=DIR``) in its own process, and
writes one JSON line per case: its name, the command, the exit status, the last line of stderr,
the number of stderr lines, a short outcome read off the result (the verdict, a p-value, the
file written) and the wall seconds. ``table`` prints the before/after table of two such runs.

Cases (issue 45, points 1-7): values beyond float32 (y and x times 1e300), plugins returning NaN,
a wrong shape, a transposed W, a hook that needs ``t`` on a file without times, ``layers``
outside the network, a planted memo entry, the long CSV's rules, the extreme noise levels, the
quantized readout, the shot + crosstalk pair, the read-only and the truncated cache, and the
smaller items. The slow cases (a diagnose each) are marked; ``--skip-slow`` leaves them out.
"""

from __future__ import annotations

import argparse
import json
import os
import stat
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

PLUGINS = {
    "nan_readout.py": '''
from gift_theory.effects import Effect, register

@register
class NanReadout(Effect):
    g: float = 1.0
    name = "nan_readout"
    params = ("g",)
    bounds = {"g": (0.1, 10.0)}
    defaults = {"g": 1.0}
    stage = "readout"
    mechanism = "readout_nonlinearity"

    def readout(self, v, noise, layer):
        return v * self.g * float("nan")
''',
    "shape_readout.py": '''
from gift_theory.effects import Effect, register

@register
class ShapeReadout(Effect):
    g: float = 1.0
    name = "shape_readout"
    params = ("g",)
    bounds = {"g": (0.1, 10.0)}
    defaults = {"g": 1.0}
    stage = "readout"
    mechanism = "readout_nonlinearity"

    def readout(self, v, noise, layer):
        return (self.g * v)[..., None]
''',
    "transposed.py": '''
from gift_theory.effects import Effect, register

@register
class Transposed(Effect):
    g: float = 1.0
    name = "transposed"
    params = ("g",)
    bounds = {"g": (0.1, 10.0)}
    defaults = {"g": 1.0}
    stage = "weights"
    mechanism = "weight_error"

    def weights(self, W, layer):
        return self.g * W.T
''',
    "needs_t.py": '''
from gift_theory.effects import Effect, register

@register
class BiasDrift(Effect):
    c: float = 0.0
    name = "bias_drift"
    params = ("c",)
    bounds = {"c": (-1.0, 1.0)}
    defaults = {"c": 0.0}
    stage = "bias"
    mechanism = "time_drift"

    def bias(self, b, layer, t):
        return b + self.c * t
''',
    "layer7.py": '''
from gift_theory.effects import Effect, register

@register
class Layer7(Effect):
    g: float = 1.0
    name = "layer7_gain"
    params = ("g",)
    bounds = {"g": (0.1, 10.0)}
    defaults = {"g": 1.0}
    stage = "readout"
    mechanism = "readout_nonlinearity"
    layers = (7,)

    def readout(self, v, noise, layer):
        return self.g * v
''',
}

MEMO_SNIPPET = '''
import os, pickle, sys
from gift_theory import _memo
folder, marker = sys.argv[1], sys.argv[2]
_memo.use_folder(folder)
key = _memo._key("direction", (1, 2))

class Bomb:
    def __reduce__(self):
        return (open, (marker, "w"))

with open(os.path.join(folder, key + ".pkl"), "wb") as fh:
    pickle.dump(Bomb(), fh)
try:
    got = _memo.memoized("direction", (1, 2), lambda: 3.0)
except Exception as exc:
    got = f"{type(exc).__name__}"
print("code ran" if os.path.exists(marker) else f"not run (value {got!r})")
'''


def _sim(code, folder, name, *extra):
    path = os.path.join(folder, name)
    _gift(code, folder, ["simulate", "--out", name, "--json", *extra])
    return path


def _gift(code, folder, args, env=None, timeout=1800):
    e = dict(os.environ, PYTHONPATH=code, **(env or {}))
    e.pop("GIFT_DEBUG", None)
    t0 = time.time()
    try:
        p = subprocess.run([sys.executable, "-c", "import sys; from gift_theory.cli import main; "
                            "sys.exit(main(sys.argv[1:]))", *args], cwd=folder, env=e, capture_output=True,
                           text=True, timeout=timeout)
        rc, out, err = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as exc:
        rc, out, err = "timeout", exc.stdout or "", f"(killed after {timeout} s)"
        out = out.decode() if isinstance(out, bytes) else out
    return rc, out, err, time.time() - t0


def _npz_times(path, key, factor):
    with np.load(path) as f:
        a = {k: f[k] for k in f.files}
    a[key] = a[key] * factor
    np.savez(path, **a)


def _json(out):
    try:
        return json.loads(out.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return None


def _verdict(out):
    j = _json(out)
    if j is None:
        return None
    if "verdict" in j:
        top = [r["effect"] for r in j.get("ranking", [])[:3]]
        mech = [m["mechanism"] for m in j.get("mechanisms", [])[:2]]
        fl = j.get("failing_layers")
        return f"{j['verdict'][:90]} | top {top} | mechanisms {mech} | failing {fl}"
    if "p_value_after" in j:
        return f"after {j['discrepancy_after']:.4g} (p = {j['p_value_after']:.3g})"
    if "p_value" in j:
        return f"p = {j['p_value']:.3g}, per layer {j.get('per_layer')}"
    if "out" in j:
        return f"wrote {j['out']}"
    return str(j)[:120]


# ---- the cases: (name, slow, function(code, folder) -> (args, env) or a finished row) --------

def c_y_1e300(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    _npz_times(os.path.join(d, "m.npz"), "y", 1e300)
    return ["compare", "m.npz", "--json", "--power-replicates", "0"]


def c_x_1e300(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    _npz_times(os.path.join(d, "m.npz"), "x", 1e300)
    return ["compare", "m.npz", "--json", "--power-replicates", "0"]


def c_y_1e20(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    _npz_times(os.path.join(d, "m.npz"), "y", 1e20)
    return ["compare", "m.npz", "--json", "--power-replicates", "0"]


def _plugin(d, name):
    with open(os.path.join(d, name), "w") as fh:
        fh.write(PLUGINS[name])
    return name


def c_fit_nan_hook(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    return ["fit", "m.npz", "--plugin", _plugin(d, "nan_readout.py"), "--add", "nan_readout", "--json", "--quiet",
            "--replicates", "2", "--power-replicates", "0"]


def c_simulate_nan_hook(code, d):
    return ["simulate", "--plugin", _plugin(d, "nan_readout.py"), "--arch", "4-6-3", "--inputs", "20",
            "--effect", "nan_readout", "--out", "sim.npz", "--json"]


def c_simulate_shape_hook(code, d):
    return ["simulate", "--plugin", _plugin(d, "shape_readout.py"), "--arch", "4-6-4", "--inputs", "20",
            "--effect", "shape_readout", "--out", "sim.npz", "--json"]


def c_transposed_hook(code, d):
    return ["simulate", "--plugin", _plugin(d, "transposed.py"), "--arch", "4-6-3", "--inputs", "20",
            "--effect", "transposed", "--out", "sim.npz", "--json"]


def c_compare_needs_t(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    return ["compare", "m.npz", "--plugin", _plugin(d, "needs_t.py"), "--effect", "awgn=0.1",
            "--effect", "bias_drift=0.5", "--json", "--power-replicates", "0"]


def c_simulate_needs_t(code, d):
    return ["simulate", "--plugin", _plugin(d, "needs_t.py"), "--arch", "4-6-3", "--inputs", "20",
            "--effect", "bias_drift=0.5", "--out", "sim.npz", "--json"]


def c_layers_outside(code, d):
    return ["simulate", "--plugin", _plugin(d, "layer7.py"), "--arch", "4-6-5-3", "--inputs", "20",
            "--effect", "layer7_gain=2", "--out", "sim.npz", "--json"]


def c_memo_pickle(code, d):
    e = dict(os.environ, PYTHONPATH=code)
    t0 = time.time()
    p = subprocess.run([sys.executable, "-c", MEMO_SNIPPET, d, os.path.join(d, "MARKER")], env=e,
                       capture_output=True, text=True)
    return {"rc": p.returncode, "outcome": (p.stdout.strip() or p.stderr.strip().splitlines()[-1])[:160],
            "stderr_last": "", "stderr_lines": 0, "seconds": time.time() - t0,
            "command": "python: plant a pickle in the memo folder, then memoized()"}


def _long_rows(code, d, one_based_neurons=False):
    """A long CSV from gift's own writer (0-based neurons before, whatever the code writes now) and
    its weights; returns (header, rows)."""
    _sim(code, d, "m.csv", "--arch", "3-4-2", "--inputs", "8", "--shots", "4", "--csv")
    with open(os.path.join(d, "m.csv")) as fh:
        lines = fh.read().splitlines()
    return lines[0], lines[1:]


def c_long_x_differs(code, d):
    header, rows = _long_rows(code, d)
    cols = header.split(",")
    # layer-0 rows of input 2 once per shot, with x1 different on shot 1
    keep, extra = [], []
    for line in rows:
        v = line.split(",")
        row = dict(zip(cols, v))
        keep.append(line)
        if row["layer"] == "0" and row["input"] == "2":
            v2 = list(v)
            v2[cols.index("shot")] = "1"
            v2[cols.index("value")] = repr(float(row["value"]) + 0.5)
            extra.append(",".join(v2))
    with open(os.path.join(d, "bad.csv"), "w") as fh:
        fh.write("\n".join([header] + keep + extra) + "\n")
    return ["compare", "bad.csv", "--weights", "m.weights.npz", "--effect", "awgn=0.1", "--json",
            "--power-replicates", "0"]


def c_long_numbering(code, d):
    """A long CSV written as docs/reference.md says (neurons 1-based) from a wide CSV's numbers."""
    _sim(code, d, "w.csv", "--arch", "3-4-2", "--inputs", "8", "--shots", "4")
    import csv
    rows = list(csv.DictReader(open(os.path.join(d, "w.csv"))))
    out = ["input,shot,layer,neuron,value"]
    for row in rows:
        i, s = int(row["input"]), int(row["shot"])
        if s == 0:
            out += [f"{i},0,0,{j},{row[f'x{j}']}" for j in range(1, 4)]
        out += [f"{i},{s},2,{j},{row[f'y{j}']}" for j in range(1, 3)]
    with open(os.path.join(d, "docs.csv"), "w") as fh:
        fh.write("\n".join(out) + "\n")
    return ["compare", "docs.csv", "--weights", "w.weights.npz", "--effect", "awgn=0.1", "--json",
            "--power-replicates", "0"]


def c_long_huge_index(code, d):
    header, rows = _long_rows(code, d)
    v = rows[-1].split(",")
    v[0] = "100000000000"
    with open(os.path.join(d, "bad.csv"), "w") as fh:
        fh.write("\n".join([header] + rows + [",".join(v)]) + "\n")
    return ["compare", "bad.csv", "--weights", "m.weights.npz", "--effect", "awgn=0.1", "--json",
            "--power-replicates", "0"]


def c_long_header_only(code, d):
    header, _ = _long_rows(code, d)
    with open(os.path.join(d, "bad.csv"), "w") as fh:
        fh.write(header + "\n")
    return ["compare", "bad.csv", "--weights", "m.weights.npz", "--effect", "awgn=0.1", "--json"]


def _diag(code, d, name, sim):
    _sim(code, d, name, *sim)
    return ["diagnose", name, "--json", "--quiet", "--power-replicates", "0"]


def c_awgn_1e6_taps(code, d):
    return _diag(code, d, "m.npz", ["--arch", "8-16-8-4", "--inputs", "120", "--shots", "32", "--taps",
                                    "--effect", "awgn=1e-6"])


def c_awgn_10_seed0(code, d):
    return _diag(code, d, "m.npz", ["--arch", "8-16-8-4", "--inputs", "120", "--shots", "32", "--taps",
                                    "--effect", "awgn=10", "--seed", "0"])


def c_awgn_10_seed1(code, d):
    return _diag(code, d, "m.npz", ["--arch", "8-16-8-4", "--inputs", "120", "--shots", "32", "--taps",
                                    "--effect", "awgn=10", "--seed", "1"])


def c_quantized_taps(code, d):
    return _diag(code, d, "m.npz", ["--arch", "10-8-6-4", "--taps", "--effect", "awgn=0.015",
                                    "--effect", "quantization=5,2"])


def c_quantized_notaps(code, d):
    return _diag(code, d, "m.npz", ["--arch", "10-8-6-4", "--effect", "awgn=0.015", "--effect", "quantization=5,2"])


def c_shot_crosstalk(code, d):
    return _diag(code, d, "m.npz", ["--arch", "16-32-16-8", "--taps", "--effect", "awgn=0.05",
                                    "--effect", "shot=0.002", "--effect", "crosstalk=0.04"])


def c_pair_small_taps(code, d):
    return _diag(code, d, "m.npz", ["--arch", "10-8-6-4", "--taps", "--effect", "awgn=0.015",
                                    "--effect", "shot=0.002", "--effect", "crosstalk=0.04"])


def c_pair_small_notaps(code, d):
    return _diag(code, d, "m.npz", ["--arch", "10-8-6-4", "--effect", "awgn=0.015",
                                    "--effect", "shot=0.002", "--effect", "crosstalk=0.04"])


def c_readonly_cache(code, d):
    ro = os.path.join(d, "ro")
    os.makedirs(ro)
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", ro], capture_output=True).returncode:
        os.chmod(ro, stat.S_IRUSR | stat.S_IXUSR)  # not root: a folder without write permission
    args = ["train", "--dataset", "digits", "--arch", "64-8-10", "--epochs", "1", "--out", "w.npz", "--json"]
    return args, {"GIFT_CACHE_DIR": os.path.join(ro, "cache")}, ro


def c_truncated_cache(code, d):
    cache = os.path.join(d, "cache")
    args = ["train", "--dataset", "digits", "--arch", "64-8-10", "--epochs", "1", "--json"]
    rc, out, err, _ = _gift(code, d, args, env={"GIFT_CACHE_DIR": cache})
    path = _json(out)["path"]
    with open(path, "r+b") as fh:
        fh.truncate(os.path.getsize(path) // 2)
    return args, {"GIFT_CACHE_DIR": cache}


def c_activation_bytes(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "40", "--shots", "16")
    with np.load(os.path.join(d, "m.npz")) as f:
        a = {k: f[k] for k in f.files}
    a["activation"] = np.array(b"tanh")
    np.savez(os.path.join(d, "m.npz"), **a)
    return ["compare", "m.npz", "--effect", "awgn=0.1", "--json", "--power-replicates", "0"]


def c_missing_w2(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-5-3", "--inputs", "40", "--shots", "16")
    with np.load(os.path.join(d, "m.npz")) as f:
        a = {k: f[k] for k in f.files if k != "W2"}
    np.savez(os.path.join(d, "m.npz"), **a)
    return ["compare", "m.npz", "--json"]


def c_not_zip(code, d):
    with open(os.path.join(d, "m.npz"), "w") as fh:
        fh.write("this is not a zip file\n" * 10)
    return ["compare", "m.npz", "--json"]


def c_three_inputs(code, d):
    _sim(code, d, "m.npz", "--arch", "4-6-3", "--inputs", "3", "--shots", "16")
    return ["diagnose", "m.npz", "--json", "--quiet"]


def c_fifo(code, d):
    os.mkfifo(os.path.join(d, "m.npz"))
    return ["compare", "m.npz", "--json"], {}, None, 60


def c_dev_zero(code, d):
    return ["compare", "/dev/zero", "--json"], {}, None, 120


CASES = {
    "y_times_1e300": (False, c_y_1e300),
    "x_times_1e300": (False, c_x_1e300),
    "y_times_1e20": (False, c_y_1e20),
    "fit_hook_returns_nan": (False, c_fit_nan_hook),
    "simulate_hook_returns_nan": (False, c_simulate_nan_hook),
    "simulate_hook_wrong_shape": (False, c_simulate_shape_hook),
    "simulate_hook_transposed_W": (False, c_transposed_hook),
    "compare_effect_needs_t": (False, c_compare_needs_t),
    "simulate_needs_t": (False, c_simulate_needs_t),
    "layers_outside_network": (False, c_layers_outside),
    "memo_planted_pickle": (False, c_memo_pickle),
    "long_csv_x_differs": (False, c_long_x_differs),
    "long_csv_docs_numbering": (False, c_long_numbering),
    "long_csv_input_1e11": (False, c_long_huge_index),
    "long_csv_header_only": (False, c_long_header_only),
    "awgn_1e-6_taps": (True, c_awgn_1e6_taps),
    "awgn_10_seed0": (True, c_awgn_10_seed0),
    "awgn_10_seed1": (True, c_awgn_10_seed1),
    "quantized_5bit_taps": (True, c_quantized_taps),
    "quantized_5bit_notaps": (True, c_quantized_notaps),
    "shot_crosstalk_pair": (True, c_shot_crosstalk),
    "shot_crosstalk_10-8-6-4_taps": (True, c_pair_small_taps),
    "shot_crosstalk_10-8-6-4_notaps": (True, c_pair_small_notaps),
    "readonly_cache_train": (True, c_readonly_cache),
    "truncated_cache_entry": (True, c_truncated_cache),
    "activation_bytes": (False, c_activation_bytes),
    "missing_W2": (False, c_missing_w2),
    "npz_not_a_zip": (False, c_not_zip),
    "three_inputs": (False, c_three_inputs),
    "fifo_path": (False, c_fifo),
    "dev_zero": (False, c_dev_zero),
}


def run_case(name, code):
    slow, fn = CASES[name]
    with tempfile.TemporaryDirectory(prefix=f"careless-{name}-") as d:
        made = fn(code, d)
        if isinstance(made, dict):
            return {"case": name, **made}
        env, mount, timeout = {}, None, 1800
        if isinstance(made, tuple):
            args, env = made[0], made[1]
            mount = made[2] if len(made) > 2 else None
            timeout = made[3] if len(made) > 3 else timeout
        else:
            args = made
        try:
            rc, out, err, sec = _gift(code, d, args, env=env, timeout=timeout)
        finally:
            if mount:
                subprocess.run(["umount", mount], capture_output=True)
        lines = [l for l in err.splitlines() if l.strip() and not l.startswith(("train ", "  warnings.warn"))]
        outcome = _verdict(out) if rc == 0 else None
        if name.startswith(("simulate_", "layers_")) and rc == 0:
            try:
                with np.load(os.path.join(d, "sim.npz")) as f:
                    y = f["y"]
                outcome = f"wrote sim.npz: y {y.shape}, finite {bool(np.isfinite(y).all())}"
            except Exception as exc:  # noqa: BLE001 - reported, not raised
                outcome = f"sim.npz unreadable: {exc}"
        if name == "readonly_cache_train":
            outcome = f"--out written: {os.path.exists(os.path.join(d, 'w.npz'))}"
        return {"case": name, "command": "gift " + " ".join(args), "rc": rc, "stderr_last": lines[-1][:300] if lines
                else "", "stderr_lines": len(lines), "outcome": outcome, "seconds": round(sec, 1)}


def table(before, after):
    b = {r["case"]: r for r in map(json.loads, open(before)) if "case" in r}
    a = {r["case"]: r for r in map(json.loads, open(after)) if "case" in r}
    print("| case | before: exit, what it said | after: exit, what it says |")
    print("|---|---|---|")
    for name in CASES:
        cells = []
        for rows in (b, a):
            r = rows.get(name)
            if r is None:
                cells.append("-")
                continue
            said = r.get("outcome") or r.get("stderr_last") or ""
            extra = f" ({r['stderr_lines']} stderr lines)" if r.get("stderr_lines", 0) > 1 else ""
            cells.append(f"{r['rc']}: {said}{extra}".replace("|", "/"))
        print(f"| {name} | {cells[0]} | {cells[1]} |")


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.careless", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out")
    r.add_argument("--code", default=HERE)
    r.add_argument("--only", default=None)
    r.add_argument("--skip-slow", action="store_true")
    t = sub.add_parser("table")
    t.add_argument("before")
    t.add_argument("after")
    a = p.parse_args(argv)
    if a.cmd == "table":
        table(a.before, a.after)
        return 0
    names = a.only.split(",") if a.only else [n for n, (slow, _) in CASES.items() if not (slow and a.skip_slow)]
    with open(a.out, "a") as out:
        for name in names:
            row = run_case(name, os.path.abspath(a.code))
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(f"{name}: rc {row['rc']} {row.get('outcome') or row.get('stderr_last')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
