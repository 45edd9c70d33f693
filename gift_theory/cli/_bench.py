"""``gift bench``: estimator speed and efficiency against the machine's own matmul rate
(reference §4). The benchmarks are :func:`gift_theory._bench.run_benchmarks`; this module
parses and prints."""

from __future__ import annotations

import sys

from ._common import positive_int


def add_arguments(parser):
    parser.add_argument("--repeats", type=positive_int, default=5, help="timed repeats per benchmark (best is reported)")
    parser.add_argument("--eff-K1", type=int, default=256, help="inputs per efficiency run (x 8 draws; at least 2)")
    parser.add_argument("--ref-K2", type=positive_int, default=64, help="draws per input of the pathwise reference")
    parser.add_argument("--quick", action="store_true", help="skip estimator_efficiency and d0_deep_million")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _log(msg):
    sys.stderr.write(f"gift bench: {msg}\n")
    sys.stderr.flush()


def run(args) -> dict:
    from .._bench import run_benchmarks

    return run_benchmarks(repeats=args.repeats, eff_K1=args.eff_K1, ref_K2=args.ref_K2, quick=args.quick,
                          log=None if args.quiet else _log)


def render(r: dict) -> str:
    lines = [f"numpy float32 matmul: {r['matmul_gflops']:.1f} GFLOP/s", ""]
    for b in r["benchmarks"]:
        if b["name"] == "estimator_efficiency":
            lines.append(f"estimator_efficiency (s0={b['s0']:g}): samples K1*K2 for 5 % relative error")
            for m, e in b["estimators"].items():
                lines.append(f"  {m:12s} {e['samples_for_5pct']:12.4g}   (observed {e['relative_error_observed']:.3f}"
                             f" vs predicted {e['relative_error_predicted']:.3f} at {e['samples']} samples)")
            lines.append(f"  pathwise needs {b['pathwise_advantage_over_score_paper']:.0f}x fewer samples than score_paper")
        elif b["name"] == "d0_deep_million":
            lines.append(f"{b['name']:18s} {b['seconds']:8.1f} s  {b['gflops']:7.1f} GFLOP/s  "
                         f"{b['ratio_to_matmul']:.2f} of matmul, peak memory {b['peak_rss_gb']:.2f} GB "
                         f"(of which input data {b['input_data_gb']:.2f} GB)")
        else:
            lines.append(f"{b['name']:18s} {b['seconds']:8.3f} s  {b['gflops']:7.1f} GFLOP/s  "
                         f"{b['ratio_to_matmul']:.2f} of matmul")
    return "\n".join(lines)
