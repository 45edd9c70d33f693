"""``gift check``: every claim of the paper as a computed verdict (CONTRACTS §4-5).

Prints a table (id, verdict, one-line evidence) or, with ``--json``, one object
``{"checks": [{id, claim, verdict, evidence, correction, counterexample}, ...]}``, and
writes a markdown report with the full evidence, corrections and counterexamples.
"""

from __future__ import annotations

import os
import sys
import time

from .._errors import GiftInputError


def add_arguments(parser):
    parser.add_argument("--precise", action="store_true", help="larger samples and searches (slower)")
    parser.add_argument("--report", default=os.path.join("gift-out", "check_report.md"),
                        help="where to write the markdown report (default gift-out/check_report.md)")
    parser.add_argument("--only", action="append", default=None, metavar="ID",
                        help="run only this check id (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed (same seed, same numbers)")


def run(args):
    from proofs_checks import CHECK_IDS, run_checks, write_report

    ids = args.only
    if ids:
        unknown = [i for i in ids if i not in CHECK_IDS]
        if unknown:
            raise GiftInputError(f"gift check --only: unknown check id {unknown[0]!r}; known: {', '.join(CHECK_IDS)}")
    report = args.report
    folder = os.path.dirname(os.path.abspath(report))
    if os.path.isdir(report):
        raise GiftInputError(f"gift check --report {report!r}: is a folder, need a file path")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise GiftInputError(f"gift check --report {report!r}: {folder} is not a folder")
    t = time.perf_counter()
    records = run_checks(ids, precise=args.precise, seed=args.seed)
    seconds = time.perf_counter() - t
    write_report(report, records, seconds=seconds, precise=args.precise)
    sys.stderr.write(f"gift check: report written to {report} ({seconds:.0f} s)\n")
    checks = [{k: r[k] for k in ("id", "claim", "verdict", "evidence", "correction", "counterexample")}
              for r in records]
    return {"checks": checks}


def render(result) -> str:
    from proofs_checks import render_table

    return render_table(result["checks"])
