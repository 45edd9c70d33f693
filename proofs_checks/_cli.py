"""``gift check`` (registered by proofs_checks): every claim of the paper as a computed verdict (reference §4-5), and
``gift check theorem1 --family FILE.py --s0 S0 --st ST``: Theorem 1 on one's own J_s family
(reference §5b).

Prints a table (id, verdict, hypotheses -- computed-true out of those a refutation needs, then the
counts of assumed hypotheses and of out-of-hypothesis findings --, one-line evidence) or, with
``--json``, one
object ``{"checks": [{id, claim, verdict, evidence, correction, counterexample, hypotheses},
...]}``, and writes a markdown report with the full evidence, hypotheses, corrections and
counterexamples.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

from gift_theory import GiftInputError
from gift_theory.cli import Progress

#: the one-line help ``gift --help`` lists (the command is registered through the entry-point
#: group ``gift.commands`` in pyproject.toml, so gift_theory never imports this package)
HELP = "every claim of the paper as a computed verdict"


def _positive_number(text: str) -> str:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number > 0 (Theorem 1 takes s0, st in (0, inf))")
    return text                      # kept as text: a sympy family reads 1.1 as 11/10 exactly


def _confidence(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must lie in (0, 1)")
    return v


def add_arguments(parser):
    parser.add_argument("target", nargs="?", choices=["theorem1"], default=None,
                        help="theorem1: check Theorem 1 on your own J_s family (needs --family, --s0, --st)")
    parser.add_argument("--precise", action="store_true", help="larger samples and searches (slower)")
    parser.add_argument("--report", default=os.path.join("gift-out", "check_report.md"),
                        help="where to write the markdown report (default gift-out/check_report.md)")
    parser.add_argument("--only", action="append", default=None, metavar="ID",
                        help="run only this check id (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed (same seed, same numbers)")
    parser.add_argument("--family", metavar="FILE.py", help="theorem1: the family file (reference §5b)")
    parser.add_argument("--s0", type=_positive_number, help="theorem1: the training noise level s0")
    parser.add_argument("--st", type=_positive_number, help="theorem1: the true noise level st")
    parser.add_argument("--confidence", type=_confidence, default=0.95,
                        help="theorem1, numeric families: accepted for compatibility; their intervals are rigorous "
                             "float64 enclosures of a finite mean, so they hold at any confidence (default 0.95)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


class _Silent:
    def write(self, _):
        pass

    def flush(self):
        pass


def _run_theorem1(args):
    from proofs_checks import FamilyError, contract_json, load_family, theorem1

    missing = [f"--{n}" for n in ("family", "s0", "st") if getattr(args, n) is None]
    if missing:
        raise GiftInputError(f"gift check theorem1: missing {', '.join(missing)}")
    try:
        fam = load_family(args.family)          # its errors name the file
    except FamilyError as exc:
        raise GiftInputError(f"gift check theorem1 --family {exc}") from None
    try:
        res = theorem1(fam, args.s0, args.st, confidence=args.confidence)
    except FamilyError as exc:
        raise GiftInputError(f"gift check theorem1 --family {args.family}: {exc}") from None
    out = contract_json(res)          # exactly the reference §5b object
    if not getattr(args, "json", False):
        out["_full"] = res             # the text form shows everything
    return out


def run(args):
    if args.target == "theorem1":
        return _run_theorem1(args)
    if args.family is not None or args.s0 is not None or args.st is not None:
        raise GiftInputError("gift check: --family/--s0/--st belong to 'gift check theorem1'")
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
    ids = tuple(ids) if ids else CHECK_IDS
    progress, log = Progress("gift check", args.quiet), (_Silent() if args.quiet else None)
    records = []
    for i, cid in enumerate(ids):   # one at a time for i/N progress (each check's key depends on its id only)
        progress(i, len(ids), cid)
        records += run_checks((cid,), precise=args.precise, seed=args.seed, log=log)
    seconds = time.perf_counter() - t
    write_report(report, records, seconds=seconds, precise=args.precise)
    if not args.quiet:
        sys.stderr.write(f"gift check: report written to {report} ({seconds:.0f} s)\n")
    keys = ("id", "claim", "verdict", "evidence", "correction", "counterexample", "hypotheses")
    return {"checks": [{k: r[k] for k in keys} for r in records]}


def render(result) -> str:
    if "_full" in result:
        from proofs_checks import render_family_result

        return render_family_result(result["_full"])
    from proofs_checks import render_table

    return render_table(result["checks"])


def demo_part(seed: int = 0, ids=("score_function_identity", "linear_example_bound"), progress=None) -> dict:
    """What ``gift demo`` shows of the checks: the claims ``ids`` as computed verdicts, and how
    many checks ``gift check`` runs in all.

    Returns
    -------
    dict ``checks`` (reference §4 records) and ``total_checks`` (the registry's size).
    """
    from proofs_checks import CHECK_IDS, run_checks

    out = []
    for i, cid in enumerate(ids):
        if progress:
            progress(i, len(ids), cid)
        out += run_checks((cid,), seed=seed, log=_Silent())
    return {"checks": out, "total_checks": len(CHECK_IDS)}
