"""Same numbers before and after a code change: compare the point files of two runs of a sweep.

``python -m paper_figures.same_numbers BEFORE_DIR AFTER_DIR [--json]``: both folders are
sweep data folders (``<dir>/<sweep>/points/<id>.json``); points are matched by their id (the
job, its fixed options and the grid point), and every numeric result both runs recorded is
compared. For each sweep and key: the number of matched points, the largest absolute and
relative difference, and -- where the AFTER run recorded a standard error ``<key>_se`` -- the
largest |difference| / se, so a change of Monte-Carlo draws (not of the quantity) shows as
differences of the order of one standard error. Job seconds are left out.
"""

from __future__ import annotations

import argparse
import json
import os
import sys


SKIP = ("seconds",)


def _points(folder: str) -> dict[str, dict[str, dict]]:
    out = {}
    if not os.path.isdir(folder):
        return out
    for sweep in sorted(os.listdir(folder)):
        pdir = os.path.join(folder, sweep, "points")
        if not os.path.isdir(pdir):
            continue
        recs = {}
        for f in os.listdir(pdir):
            if f.endswith(".json"):
                with open(os.path.join(pdir, f)) as fh:
                    recs[f[:-5]] = json.load(fh)
        out[sweep] = recs
    return out


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def compare(before: str, after: str) -> dict:
    """{sweep: {key: {"n", "max_abs", "max_rel", "max_z" (or None), "changed"}}} plus unmatched counts."""
    a, b = _points(before), _points(after)
    out = {}
    for sweep in sorted(set(a) & set(b)):
        common = sorted(set(a[sweep]) & set(b[sweep]))
        rows = {}
        for pid in common:
            ra, rb = a[sweep][pid]["result"], b[sweep][pid]["result"]
            for k, va in ra.items():
                vb = rb.get(k)
                if k in SKIP or not (_number(va) or isinstance(va, bool)) or vb is None:
                    continue
                va, vb = float(va), float(vb)
                se = rb.get(f"{k}_se")
                d = abs(vb - va)
                r = rows.setdefault(k, {"n": 0, "max_abs": 0.0, "max_rel": 0.0, "max_z": None, "changed": 0})
                r["n"] += 1
                r["max_abs"] = max(r["max_abs"], d)
                r["max_rel"] = max(r["max_rel"], d / max(abs(va), 1e-300) if d > 0 else 0.0)
                if _number(se) and se > 0:
                    r["max_z"] = max(r["max_z"] or 0.0, d / se)
                r["changed"] += int(d > 1e-5 * max(abs(va), 1e-12))
        out[sweep] = {"matched": len(common), "only_before": len(set(a[sweep]) - set(b[sweep])),
                      "only_after": len(set(b[sweep]) - set(a[sweep])), "keys": rows}
    return out


def render(r: dict) -> str:
    lines = []
    for sweep, s in r.items():
        lines.append(f"{sweep}: {s['matched']} points matched ({s['only_before']} only before, "
                     f"{s['only_after']} only after)")
        for k, v in s["keys"].items():
            z = f", max |diff|/se {v['max_z']:.2f}" if v["max_z"] is not None else ""
            lines.append(f"  {k:24s} max |diff| {v['max_abs']:.3g} (relative {v['max_rel']:.3g}); "
                         f"{v['changed']}/{v['n']} beyond 1e-5 relative{z}")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m paper_figures.same_numbers", description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    for d in (args.before, args.after):
        if not os.path.isdir(d):
            sys.stderr.write(f"{d}: no such folder\n")
            return 2
    r = compare(args.before, args.after)
    sys.stdout.write((json.dumps(r) if args.json else render(r)) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
