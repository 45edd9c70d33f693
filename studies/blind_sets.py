"""Every blind set, written and scored file by file, resumable: the before/after record of a lab change.

    python -m studies.blind_sets FILES_DIR OUT_DIR [--sets open_nt,open_t,...] [--write-only]
    python -m studies.blind_sets FILES_DIR OUT_DIR --table            (rows and tables from the kept JSON)
    python -m studies.blind_sets FILES_DIR OUT_DIR --compare BEFORE_DIR   (every set's counts, before -> after)

Each set is written once (``FILES_DIR/<set>``, by :func:`studies.blind.main` with the set's
arguments below; the files depend only on those arguments, never on the code under test) and
scored by ``gift diagnose FILE --json --seed i --quiet`` (``--no-design``: with ``--no-design``, which
changes no scored field) in this process, i the file's index in
its folder (the seeds of ``python -m studies.blind score``). Each file's whole JSON is kept
(``OUT_DIR/json_<set>/FILE.json``); a file whose JSON is there is not run again, so a killed run
resumes where it stopped. ``--table`` scores the kept JSON (:func:`studies.blind.score_row`)
into ``OUT_DIR/<set>.jsonl`` and prints the markdown tables of :func:`studies.blind.table`.

The sets (``SETS``) are those of ``studies/results/2026-11-28`` section 3 -- open and built-in
physics scored on file 0 of each (``_0.``), the issue-24 set, the MZI mesh, the drift and
common-mode set -- and the time set of issue 48 (``--physics time``: slow intensity wander,
drifting weights, detector memory, activation shapes; every file).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

#: set -> (arguments of ``python -m studies.blind write``, the files scored: a name fragment or None for all)
SETS = {
    "open_nt": (["--physics", "open", "--files-per-physics", "4", "--seed", "14", "--no-taps"], "_0."),
    "new_nt": (["--physics", "new", "--no-taps"], None),
    "mesh_nt": (["--physics", "mesh", "--no-taps"], None),
    "builtin_nt": (["--files-per-effect", "4", "--seed", "2", "--no-taps"], "_0."),
    "open_t": (["--physics", "open", "--files-per-physics", "4", "--seed", "14"], "_0."),
    "new_t": (["--physics", "new"], None),
    "mesh_t": (["--physics", "mesh"], None),
    "builtin_t": (["--files-per-effect", "4", "--seed", "2"], "_0."),
    "drift_t": (["--physics", "builtin", "--effects", "drift,common_mode", "--files-per-effect", "3", "--seed", "2"],
                None),
    "time_nt": (["--physics", "time", "--files-per-physics", "3", "--seed", "48", "--no-taps"], None),
    "time_t": (["--physics", "time", "--files-per-physics", "3", "--seed", "48"], None),
}
#: the sets that existed before issue 48 (the ones no count may fall on)
STANDING = ("open_nt", "new_nt", "mesh_nt", "builtin_nt", "open_t", "new_t", "mesh_t", "builtin_t", "drift_t")


def _write(folder: str, name: str) -> None:
    from . import blind

    if os.path.isdir(folder) and any(f.endswith(".npz") for f in os.listdir(folder)):
        return
    args, _ = SETS[name]
    rc = blind.main(["write", folder] + args)
    if rc:
        raise SystemExit(f"writing {name} failed ({rc})")


def _chosen(folder: str, name: str, only=None):
    """(index, file) of the set's scored files (the index in the folder: the file's seed);
    ``only``: a name fragment that further restricts them (a smaller run, said as such)."""
    files = sorted(f for f in os.listdir(folder) if f.endswith(".npz"))
    match = SETS[name][1]
    return [(i, f) for i, f in enumerate(files) if (match is None or match in f) and (only is None or only in f)]


def run(files_dir: str, out_dir: str, sets, write_only: bool = False, extra=(), only=None) -> None:
    from .blind import run_diagnose

    for name in sets:
        folder = os.path.join(files_dir, name)
        _write(folder, name)
        if write_only:
            continue
        keep = os.path.join(out_dir, f"json_{name}")
        os.makedirs(keep, exist_ok=True)
        todo = [(i, f) for i, f in _chosen(folder, name, only) if not os.path.exists(os.path.join(keep, f[:-4] + ".json"))]
        for k, (i, f) in enumerate(todo):
            t0 = time.time()
            res, err = run_diagnose(os.path.join(folder, f), i, extra=extra)
            if res is None:
                res = {"error": err}
            res["study_seconds"] = time.time() - t0
            tmp = os.path.join(keep, f[:-4] + ".json.tmp")
            with open(tmp, "w") as fh:
                json.dump(res, fh)
            os.replace(tmp, os.path.join(keep, f[:-4] + ".json"))
            sys.stderr.write(f"[{name} {k + 1}/{len(todo)}] {f}: {res.get('verdict', err)} "
                             f"({res['study_seconds']:.0f} s)\n")
            sys.stderr.flush()


def rows(files_dir: str, out_dir: str, sets) -> list[str]:
    """Score the kept JSON of each set into ``OUT_DIR/<set>.jsonl``; returns the paths written."""
    from .blind import _row, _shape, builtin_label

    paths = []
    for name in sets:
        folder = os.path.join(files_dir, name)
        keep = os.path.join(out_dir, f"json_{name}")
        if not os.path.isdir(keep):
            continue
        labels = None
        if os.path.exists(os.path.join(folder, "labels.json")):
            with open(os.path.join(folder, "labels.json")) as fh:
                labels = json.load(fh)
        out = []
        for i, f in _chosen(folder, name):
            path = os.path.join(keep, f[:-4] + ".json")
            if not os.path.exists(path):
                continue
            with open(path) as fh:
                res = json.load(fh)
            label = labels[f] if labels is not None else builtin_label(os.path.join(folder, f))
            err = res.get("error")
            out.append(_row(f, label, _shape(os.path.join(folder, f)), None if err else res, err,
                            builtin=labels is None))
        dest = os.path.join(out_dir, f"{name}.jsonl")
        with open(dest, "w") as fh:
            for r in out:
                fh.write(json.dumps(r) + "\n")
        paths.append(dest)
    return paths


#: the columns of the before/after table: (name, rows counted, field, a higher count is better)
COLUMNS = (("detected", "effects", "detected", True), ("false alarms", "nulls", "detected", False),
           ("explained correct", "all", "explained_correct", True),
           ("wrong explanations", "all", "wrong_explanation", False),
           ("first class right", "effects", "mechanism_first", True),
           ("failing layers exact", "all", "failing_layers_exact", True),
           ("rejected first", "all", "rejected_first", False))


def _files(path: str) -> set:
    with open(path) as f:
        return {json.loads(line)["file"] for line in f if line.strip()}


def counts(path: str, files=None) -> dict:
    """``{column: (count, of)}`` of one set's scored rows (:data:`COLUMNS`); ``files``: only
    these files' rows."""
    with open(path) as f:
        rs = [json.loads(line) for line in f if line.strip()]
    rs = [r for r in rs if not r.get("error") and (files is None or r["file"] in files)]
    out = {}
    for name, which, field, _ in COLUMNS:
        sel = [r for r in rs if which == "all" or (which == "nulls") == (r["physics"] == "none")]
        vals = [r.get(field) for r in sel if r.get(field) is not None]
        out[name] = (int(sum(bool(v) for v in vals)), len(vals))
    return out


def compare(files_dir: str, before: str, after: str, sets) -> str:
    """The markdown table of every set's counts before and after (each column "before -> after",
    a count that got worse marked **), from the kept JSON of both runs."""
    rows(files_dir, before, sets)
    rows(files_dir, after, sets)
    head = "| set | " + " | ".join(c[0] for c in COLUMNS) + " |\n|---|" + "---|" * len(COLUMNS) + "\n"
    lines = []
    for name in sets:
        pb, pa = os.path.join(before, f"{name}.jsonl"), os.path.join(after, f"{name}.jsonl")
        if not (os.path.exists(pb) and os.path.exists(pa)):
            continue
        both = _files(pb) & _files(pa)  # the files both runs scored
        cb, ca = counts(pb, both), counts(pa, both)
        cells = []
        for col, _, _, higher in COLUMNS:
            (kb, nb), (ka, na) = cb[col], ca[col]
            if not nb and not na:
                cells.append("-")
                continue
            worse = (ka < kb) if higher else (ka > kb)
            cell = f"{kb}/{nb} -> {ka}/{na}"
            cells.append(f"**{cell}**" if worse else cell)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.blind_sets", description=__doc__.split("\n\n")[0])
    p.add_argument("files_dir")
    p.add_argument("out_dir")
    p.add_argument("--sets", default=",".join(SETS), help="comma-separated set names (default: all)")
    p.add_argument("--write-only", action="store_true", help="write the sets' files, score nothing")
    p.add_argument("--table", action="store_true", help="rows and markdown tables from the kept JSON")
    p.add_argument("--compare", default=None, metavar="BEFORE_DIR",
                   help="the before/after table of every set's counts: BEFORE_DIR's kept JSON against OUT_DIR's")
    p.add_argument("--match", default=None, metavar="TEXT",
                   help="score only the set's files whose name holds TEXT (a smaller run; --table and --compare "
                        "count the files both runs scored)")
    p.add_argument("--no-design", action="store_true",
                   help="gift diagnose --no-design (no next measurement: every scored field is the same, in less time)")
    a = p.parse_args(argv)
    sets = [s.strip() for s in a.sets.split(",") if s.strip()]
    bad = [s for s in sets if s not in SETS]
    if bad:
        sys.stderr.write(f"python -m studies.blind_sets: unknown set {bad[0]!r}; known: {', '.join(SETS)}\n")
        return 2
    if a.compare:
        sys.stdout.write(compare(a.files_dir, a.compare, a.out_dir, sets))
        return 0
    if a.table:
        from .blind import table

        table(rows(a.files_dir, a.out_dir, sets))
        return 0
    run(a.files_dir, a.out_dir, sets, a.write_only, extra=("--no-design",) if a.no_design else (), only=a.match)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
