"""The identification's rows on the standing blind sets' scored files, to find the files a lab change touches.

    python blind_ident.py OUT.jsonl FILES_DIR [PART PARTS]    # resumable; FILES_DIR as for studies.blind_sets
    python blind_ident.py --diff BEFORE.jsonl AFTER.jsonl      # the files whose rows differ (p beyond 1e-9 relative)

Only the files whose rows differ can have another diagnosis; score those before and after with
``python -m studies.blind_sets FILES_DIR OUT --sets SET --match NAME.`` and compare.
"""
import json
import os
import sys
import time


def _standing(files_dir):
    from studies.blind_sets import STANDING, _chosen

    return [os.path.join(files_dir, n, f) for n in STANDING for _, f in _chosen(os.path.join(files_dir, n), n)]


def run(out, files_dir, part=0, parts=1):
    from gift_theory.lab import identify, load_measurement

    done = {json.loads(line)["file"] for line in open(out)} if os.path.exists(out) else set()
    with open(out, "a") as fh:
        for f in _standing(files_dir)[part::parts]:
            if f in done:
                continue
            t0 = time.time()
            try:
                rows = [[r["class"], r["test"], r.get("layer"), float(r["p"]), float(r.get("p_adj", 1.0))]
                        for r in identify(load_measurement(f)).rows()]
            except Exception as e:  # a crash is a finding of its own: kept, not fatal to the run
                rows = f"ERROR {type(e).__name__}: {str(e)[:100]}"
            fh.write(json.dumps({"file": f, "rows": rows, "sec": time.time() - t0}) + "\n")
            fh.flush()


def diff(before, after):
    load = lambda p: {json.loads(line)["file"]: json.loads(line)["rows"] for line in open(p)}
    a, b = load(before), load(after)
    common = sorted(set(a) & set(b))
    changed = 0
    for f in common:
        ra, rb = a[f], b[f]
        if isinstance(ra, str) or isinstance(rb, str) or len(ra) != len(rb):
            if ra != rb:
                changed += 1
                print(f, "error" if isinstance(ra, str) or isinstance(rb, str) else "rows differ")
            continue
        moved = [(x[0], x[1], x[2], x[3], y[3]) for x, y in zip(ra, rb)
                 if x[:3] != y[:3] or abs(x[3] - y[3]) > 1e-9 * max(abs(x[3]), 1e-300) + 1e-15]
        na, nb = {(x[0], x[2]) for x in ra if x[4] < 0.01}, {(x[0], x[2]) for x in rb if x[4] < 0.01}
        if moved or na != nb:
            changed += 1
            print(f, "named changed: " + str(sorted(na ^ nb)) if na != nb else "",
                  [f"{m[0]} {m[1]} layer {m[2]}: {m[3]:.3g} -> {m[4]:.3g}" for m in moved[:4]])
    print(f"{len(common)} files, {changed} with other rows")


if __name__ == "__main__":
    if sys.argv[1] == "--diff":
        diff(sys.argv[2], sys.argv[3])
    else:
        run(sys.argv[1], sys.argv[2], *(int(a) for a in sys.argv[3:5]))
