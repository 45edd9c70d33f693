"""A mutation pass over proofs_checks: does some test fail when a check's decisive code is changed?

For each check id, the functions that make up its decisive computation (``TARGETS``) are mutated
one syntax node at a time -- a comparison flipped (< <=, > >=, == !=, is / is not, in / not in),
``and``/``or`` swapped, a ``not`` dropped, an arithmetic operator swapped (+ -, * /), ``all``/``any``
and ``max``/``min`` swapped, a numeric literal changed (n -> n + 1, x -> 2 x, 0 -> 1), ``True``/``False``
swapped -- never inside a string or an f-string (evidence text decides nothing). Each mutant is
run against the check's tests (``TARGETS[id]["tests"]``); it is *killed* when a test fails (or
errors, or exceeds the time limit), *survived* otherwise. ``SLIPS`` adds the two hand-made slips
of issue 44 (``any`` for ``all`` in linear_example_bound; the toy's E Var(f|A) replaced by Var f in
hierarchical_sampling's variance formula).

Mutants of one check run in one process (``--jobs`` processes at a time): the mutated module is
executed into the live module object, every reference to its old functions elsewhere in
proofs_checks (re-exports, the registry, ``from ... import``) is rebound, the shared ONN setup is
rebuilt only when the mutated module can change it, and pytest runs in-process.

    python tools/mutation_pass.py                       # every check, 24 mutants each, 2 jobs
    python tools/mutation_pass.py --check hierarchical_sampling --check linear_example_bound
    python tools/mutation_pass.py --list                # the mutants, without running them

Prints a table (check, killed / tried, survivors) and writes the survivors with their
locations to ``--out`` (default gift-out/mutation_pass.json). Not part of the library.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import signal
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

T = "tests/proofs/test_checks.py"

#: check id -> the functions of its decisive computation (module, qualified name) and its tests
TARGETS = {
    "lemma_gaussian_product_derivative": dict(
        code=[("_symbolic", "gaussian_product"), ("_symbolic", "lemma_difference"),
              ("_symbolic", "lemma_gaussian_product_derivative"), ("_symbolic", "_gaussian_density_hypothesis")],
        tests=[f"{T}::test_lemma_gaussian_product_derivative", "tests/proofs/test_symbolic.py::test_lemma_printed_fails_corrected_holds"]),
    "backprop_formulas": dict(
        code=[("_symbolic", "_network"), ("_symbolic", "backprop_difference"), ("_symbolic", "backprop_formulas"),
              ("_symbolic", "_generic_sigma_hypothesis")],
        tests=[f"{T}::test_backprop_formulas", "tests/proofs/test_symbolic.py::test_backprop_holds_and_broken_variant_fails"]),
    "score_function_identity": dict(
        code=[("_symbolic", "_gauss_expect"), ("_symbolic", "score_identity_difference"),
              ("_symbolic", "score_function_identity"), ("_symbolic", "_noise_hypothesis")],
        tests=[f"{T}::test_score_function_identity", "tests/proofs/test_symbolic.py::test_score_identity_ratio_is_minus_s_over_2",
               "tests/proofs/test_symbolic.py::test_score_identity_beyond_one_neuron_per_layer"]),
    "d0_limit": dict(
        code=[("_sampling", "d0_comparison"), ("_sampling", "d0_limit"), ("_sampling", "lemma_hypotheses_onn")],
        tests=[f"{T}::test_d0_limit"]),
    "hierarchical_sampling": dict(
        code=[("_sampling", "toy_moments"), ("_sampling", "hierarchical_toy"), ("_sampling", "_var_test"),
              ("_sampling", "hierarchical_sampling")],
        tests=[f"{T}::test_hierarchical_sampling"]),
    "sgd_limit_points": dict(
        code=[("_sgd", "steps_hypothesis"), ("_sgd", "exact_grad"), ("_sgd", "sgd_limit_points")],
        tests=["tests/proofs/test_sgd.py::test_step_size_hypothesis_decided_by_sympy",
               "tests/proofs/test_sgd.py::test_exact_gradient_vanishes_at_the_interior_minimiser",
               f"{T}::test_sgd_limit_points"]),
    "square_integrability": dict(
        code=[("_sampling", "fourth_moments"), ("_sampling", "stabilises"), ("_sampling", "square_integrability")],
        tests=[f"{T}::test_square_integrability", "tests/proofs/test_sampling.py::test_fourth_moment_stabiliser_known_cases"]),
    "theorem1_condition": dict(
        code=[("_theorem1", "family_quantities"), ("_theorem1", "nearest_zero_of_C1"), ("_theorem1", "search_families"),
              ("_theorem1", "taylor_steps"), ("_theorem1", "theorem1_condition")],
        tests=[f"{T}::test_theorem1_condition"] + [f"tests/proofs/test_theorem1.py::{t}" for t in (
            "test_wrong_sign_gives_a_zero_of_C1_inside_the_printed_condition", "test_search_counts",
            "test_corrected_condition_implies_descent", "test_condition_record")]),
    "theorem1_conclusion": dict(
        code=[("_theorem1", "theorem1_conclusion"), ("_theorem1", "descent_confirmation")],
        tests=[f"{T}::test_theorem1_conclusion"]),
    "theorem2_guarantee": dict(
        code=[("_gift", "global_minimiser_1d"), ("_gift", "algorithm1_exact"), ("_gift", "theorem2_printed"),
              ("_gift", "theorem2_guarantee"), ("_gift", "_theorem2_correction"), ("_gift", "_theorem2_exact_rows")],
        tests=["tests/proofs/test_hypotheses.py::test_theorem2_as_printed_is_refuted_inside_its_hypotheses",
               f"{T}::test_theorem2_algorithm1_exact_reports_a_difference", f"{T}::test_theorem2_guarantee"]),
    "linear_example_bound": dict(
        code=[("_linear", "mc_cross_check"), ("_linear", "c1_closed_form"), ("_linear", "_example_hypotheses"),
              ("_linear", "linear_example_bound")],
        tests=[f"{T}::test_linear_example_bound", f"{T}::test_linear_example_bound_can_hold"]),
    "gift_never_worse": dict(
        code=[("_gift", "algorithm1"), ("_gift", "_clopper_pearson"), ("_gift", "_corrected_runs"),
              ("_gift", "corrected_selection_verdict"), ("_gift", "gift_never_worse")],
        tests=["tests/proofs/test_gift_alg.py", f"{T}::test_corrected_selection_verdict", f"{T}::test_gift_never_worse"]),
    "algorithm1_stopping_rule": dict(
        code=[("_gift", "stopping_rule_exact"), ("_gift", "stopping_rule_verdict"), ("_gift", "algorithm1_stopping_rule")],
        tests=[f"{T}::test_stopping_rule_verdict", f"{T}::test_algorithm1_stopping_rule"]),
    "proposition1_ode_limit": dict(
        code=[("_sgd", "ode_shadowing"), ("_sgd", "proposition1_ode_limit")],
        tests=[f"{T}::test_proposition1_ode_limit"]),
    "hierarchical_borel_cantelli": dict(
        code=[("_sampling_proofs", "schedule_table"), ("_sampling_proofs", "hierarchical_borel_cantelli")],
        tests=[f"{T}::test_hierarchical_borel_cantelli"]),
    "d0_covariance_identity": dict(
        code=[("_sampling_proofs", "moment_symbols"), ("_sampling_proofs", "covariance_identity"), ("_sampling_proofs", "bound_violations"),
              ("_sampling_proofs", "d0_covariance_identity")],
        tests=[f"{T}::test_d0_covariance_identity", f"{T}::test_d0_covariance_identity_moments_hypothesis_can_fail"]),
    "gift_taylor_rule": dict(
        code=[("_taylor", "flat_direction_family"), ("_taylor", "linear_side"), ("_taylor", "gift_taylor_rule")],
        tests=[f"{T}::test_gift_taylor_rule"]),
    "linear_example_text_claim": dict(
        code=[("_linear", "linear_example_text_claim")],
        tests=[f"{T}::test_linear_example_text_claim", f"{T}::test_linear_example_text_claim_needs_v_zero_at_every_depth"]),
    "proposition2_unique_point": dict(
        code=[("_kushner", "proposition2_unique_point")],
        tests=[f"{T}::test_proposition2_unique_point"]),
    "kushner_verification": dict(
        code=[("_kushner", "_symbolic_grad_moment"), ("_kushner", "kushner_verification")],
        tests=[f"{T}::test_kushner_verification"]),
    "linear_example_v_scaling": dict(
        code=[("_linear", "vector_example"), ("_linear", "linear_example_v_scaling")],
        tests=["tests/proofs/test_hypotheses.py::test_vector_linear_example_corrected_bound_is_free_of_V",
               f"{T}::test_linear_example_v_scaling"]),
    "(shared) Theorem-1 checker": dict(
        code=[("_family_numeric", "critical_certificate"), ("_family_numeric", "_theorem1_numeric"),
              ("_family_numeric", "_numeric_conditions"), ("_family_numeric", "_wt_row"),
              ("_family_sympy", "_theorem1_sympy"), ("_family_sympy", "_conditions_exact"),
              ("_exact", "_critical_points"), ("_exact", "exact_sup_abs"),
              ("_exact", "_zero_proven"), ("_interval", "krawczyk"), ("_mc", "trivial_point_certificate"),
              ("_mc", "symmetric_draws")],
        tests=["tests/proofs/test_family.py::test_quartic_exact",
               "tests/proofs/test_interval.py::test_krawczyk_certifies_a_simple_zero_and_refuses_a_degenerate_one",
               "tests/proofs/test_family.py::test_per_sample_non_critical_family_is_outside_never_a_counterexample",
               "tests/proofs/test_hypotheses.py::test_non_critical_w0_is_outside_never_a_counterexample",
               "tests/proofs/test_hypotheses.py::test_rounded_critical_points_are_certified_by_krawczyk",
               "tests/proofs/test_hypotheses.py::test_st_equal_s0_is_outside",
               "tests/proofs/test_family.py::test_linear_chains_against_closed_forms",
               "tests/proofs/test_family.py::test_numeric_copy_matches_sympy",
               "tests/proofs/test_family.py::test_trivial_point_certificate",
               "tests/proofs/test_hypotheses.py::test_theorem2_as_printed_is_refuted_inside_its_hypotheses",
               "tests/proofs/test_cli.py::test_theorem1_subcommand_quartic_json",
               f"{T}::test_theorem1_condition"]),
    "(shared) verdict rules": dict(
        code=[("_record", "record"), ("_record", "decide"), ("_record", "equality_verdict"), ("_record", "sign_verdict"),
              ("_record", "combine"), ("_record", "symbolic_verdict")],
        tests=["tests/proofs/test_record.py"]),
}

#: the two slips of issue 44, as (check, module, old text, new text)
SLIPS = [
    ("linear_example_bound", "_linear", 'symbolic_verdict(all(r["diff"] == 0 for r in rows))',
     'symbolic_verdict(any(r["diff"] == 0 for r in rows))'),
    ("hierarchical_sampling", "_sampling", "var_formula = var_g / K1 + E_var / (K1 * K2)",
     "var_formula = var_g / K1 + var_f / (K1 * K2)"),
]

#: modules whose change can alter the shared ONN setup (proofs_checks._onn._CACHE is then rebuilt)
_SETUP_MODULES = {"_family", "_family_check", "_family_numeric", "_family_result", "_interval", "_mc", "_onn",
                  "_symbolic"}

_CMP = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt, ast.Eq: ast.NotEq, ast.NotEq: ast.Eq,
        ast.Is: ast.IsNot, ast.IsNot: ast.Is, ast.In: ast.NotIn, ast.NotIn: ast.In}
_BIN = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult}
_CALLS = {"all": "any", "any": "all", "max": "min", "min": "max"}


# --------------------------------------------------------------------------------------
# generating mutants
# --------------------------------------------------------------------------------------
def _find_function(tree, name):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == name:
            return node
    raise KeyError(name)


#: calls whose integer arguments are PRNG seeds or keys (not mutated: another seed is another instance)
_SEED_CALLS = {"PRNGKey", "fold_in", "split", "default_rng", "randint", "key"}
#: names that hold sample sizes, step counts, precision or the size of a search (not mutated: a verdict
#: must not hinge on their exact value, and n -> n + 1 is no slip)
_SIZE_NAMES = {"R", "Rm", "n", "N", "K1", "K2", "K2e", "K2m", "steps", "n_laws", "max_L", "dps", "blocks", "windows",
               "max_iter", "max_pieces", "substeps", "order", "tries", "groups", "n_int", "configs"}


def _evidence_only_names(fn):
    """Names assigned in ``fn`` whose every use is inside an f-string (evidence text), directly or through
    other such names: what they hold decides nothing."""
    in_text = set()
    for node in ast.walk(fn):
        if isinstance(node, ast.JoinedStr):
            in_text.update(id(n) for n in ast.walk(node))
    assigned = {}
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign) and all(isinstance(t, ast.Name) for t in node.targets):
            for t in node.targets:
                assigned.setdefault(t.id, []).append(node)
    loads = {}
    for stmt in ast.walk(fn):
        for n in ast.walk(stmt):
            if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load):
                loads.setdefault(n.id, set()).add(id(n))
    owner = {}                                     # load id -> the names whose assignment contains it
    for name, stmts in assigned.items():
        for st in stmts:
            for n in ast.walk(st.value):
                if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load):
                    owner.setdefault(id(n), set()).add(name)
    evidence = set()
    changed = True
    while changed:
        changed = False
        for name in assigned:
            if name in evidence or name not in loads:
                continue
            if all(i in in_text or (owner.get(i) and owner[i] <= evidence) for i in loads[name]):
                evidence.add(name)
                changed = True
    return evidence


def _skipped(fn):
    """Node ids not to mutate: the docstring, strings and f-strings (evidence text), values assigned to
    names used only in evidence text, argument defaults, the arguments of seed calls, the values assigned
    to size names (``_SIZE_NAMES``) and size keywords (``K2=...``)."""
    skip = set()
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        skip.update(id(n) for n in ast.walk(body[0]))
    skip.update(id(n) for d in fn.args.defaults + fn.args.kw_defaults if d is not None for n in ast.walk(d))
    text_only = _evidence_only_names(fn)
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign) and all(isinstance(t, ast.Name) and t.id in text_only for t in node.targets):
            skip.update(id(n) for n in ast.walk(node.value))
    for node in ast.walk(fn):
        if isinstance(node, ast.JoinedStr):
            skip.update(id(n) for n in ast.walk(node))
        elif isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if name in _SEED_CALLS:
                skip.update(id(n) for a in node.args for n in ast.walk(a) if isinstance(n, ast.Constant))
            for kw in node.keywords:
                if kw.arg in _SIZE_NAMES:
                    skip.update(id(n) for n in ast.walk(kw.value))
        elif isinstance(node, ast.Assign) and all(isinstance(t, ast.Name) and t.id in _SIZE_NAMES
                                                  for t in node.targets):
            skip.update(id(n) for n in ast.walk(node.value))
        elif isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Tuple):
            for t, v in zip(node.targets[0].elts, getattr(node.value, "elts", [])):
                if isinstance(t, ast.Name) and t.id in _SIZE_NAMES:
                    skip.update(id(n) for n in ast.walk(v))
    return skip


def _mutations(node):
    """The mutations of one node: (description, apply, undo) with apply/undo changing the node in place."""
    out = []

    def setter(obj, attr, new):
        old = getattr(obj, attr)
        return (lambda: setattr(obj, attr, new)), (lambda: setattr(obj, attr, old))

    if isinstance(node, ast.Compare):
        for i, op in enumerate(node.ops):
            new = _CMP.get(type(op))
            if new is not None:
                def apply(i=i, new=new):
                    node.ops[i] = new()

                def undo(i=i, op=op):
                    node.ops[i] = op
                out.append((f"{type(op).__name__} -> {new.__name__}", apply, undo))
    elif isinstance(node, ast.BoolOp):
        new = ast.Or if isinstance(node.op, ast.And) else ast.And
        out.append((f"{type(node.op).__name__} -> {new.__name__}",) + setter(node, "op", new()))
    elif isinstance(node, ast.BinOp) and type(node.op) in _BIN:
        new = _BIN[type(node.op)]
        out.append((f"{type(node.op).__name__} -> {new.__name__}",) + setter(node, "op", new()))
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _CALLS:
        new = _CALLS[node.func.id]
        out.append((f"{node.func.id}() -> {new}()",) + setter(node.func, "id", new))
    elif isinstance(node, ast.Constant) and type(node.value) in (int, float, bool):
        v = node.value
        new = (not v) if isinstance(v, bool) else (v + 1 if isinstance(v, int) else (1.0 if v == 0 else 2 * v))
        out.append((f"{v!r} -> {new!r}",) + setter(node, "value", new))
    return out


def _not_drops(fn, skip):
    """(description, apply, undo) for every ``not x`` in ``fn``: replaced by ``x`` in its parent."""
    out = []
    for parent in ast.walk(fn):
        if id(parent) in skip:
            continue
        for field, value in ast.iter_fields(parent):
            items = list(enumerate(value)) if isinstance(value, list) else [(None, value)]
            for i, child in items:
                if isinstance(child, ast.UnaryOp) and isinstance(child.op, ast.Not) and id(child) not in skip:
                    def apply(parent=parent, field=field, i=i, child=child):
                        if i is None:
                            setattr(parent, field, child.operand)
                        else:
                            getattr(parent, field)[i] = child.operand

                    def undo(parent=parent, field=field, i=i, child=child):
                        if i is None:
                            setattr(parent, field, child)
                        else:
                            getattr(parent, field)[i] = child
                    out.append((child, "drop not", apply, undo))
    return out


def mutants_of(module: str, func: str):
    """Every mutant of ``func`` in proofs_checks/``module``.py: dicts (module, function, line, what, source)."""
    path = os.path.join(ROOT, "proofs_checks", f"{module}.py")
    tree = ast.parse(open(path).read())
    fn = _find_function(tree, func)
    skip = _skipped(fn)
    todo = [(n, what, apply, undo) for n in ast.walk(fn) if id(n) not in skip for what, apply, undo in _mutations(n)]
    todo += _not_drops(fn, skip)
    out = []
    for node, what, apply, undo in todo:
        apply()
        try:
            source = ast.unparse(tree)
        finally:
            undo()
        out.append(dict(module=module, function=func, line=getattr(node, "lineno", 0), what=what, source=source))
    return out


def slip_mutants(check):
    out = []
    for cid, module, old, new in SLIPS:
        if cid != check:
            continue
        src = open(os.path.join(ROOT, "proofs_checks", f"{module}.py")).read()
        if old not in src:
            raise SystemExit(f"tools/mutation_pass.py: the slip {old!r} is not in proofs_checks/{module}.py")
        line = src[:src.index(old)].count("\n") + 1
        out.append(dict(module=module, function="(issue 44 slip)", line=line, what=f"{old} -> {new}",
                        source=src.replace(old, new, 1), slip=True))
    return out


# --------------------------------------------------------------------------------------
# running mutants (in one process per check)
# --------------------------------------------------------------------------------------
class _Timeout(Exception):
    pass


def _rebind(module_name, old_ns, new_ns):
    """Point every reference to a function of the old module at its new version."""
    olds = {id(v): k for k, v in old_ns.items() if callable(v)}
    for name, mod in list(sys.modules.items()):
        if not (name.startswith("proofs_checks") or name.startswith("tests")) or mod is None:
            continue
        for attr, val in list(vars(mod).items()):
            if id(val) in olds and olds[id(val)] in new_ns:
                setattr(mod, attr, new_ns[olds[id(val)]])
    reg = sys.modules["proofs_checks._registry"]
    for cid, fn in list(reg.CHECKS.items()):
        if id(fn) in olds and olds[id(fn)] in new_ns:
            reg.CHECKS[cid] = new_ns[olds[id(fn)]]


def _load(module, source):
    import importlib

    mod = importlib.import_module(f"proofs_checks.{module}")
    old = dict(vars(mod))
    exec(compile(source, mod.__file__, "exec"), vars(mod))
    _rebind(module, old, vars(mod))
    return old


def run_check(check, mutants, timeout, log):
    """Run the mutants of one check in this process; returns a list of results."""
    import pytest

    os.chdir(ROOT)
    sys.path.insert(0, ROOT)
    tests = TARGETS[check]["tests"]
    args = ["-x", "-q", "-p", "no:cacheprovider", "-p", "no:randomly", "--no-header", "-o", "addopts=",
            "--import-mode=importlib", "-W", "ignore::pytest.PytestAssertRewriteWarning"] + tests

    def run_tests(limit=None):
        # the alarm's exception is raised inside a test, where pytest reports it as that test's failure (exit 1):
        # the flag tells a timeout from a failing test
        fired = []

        def alarm(*_):
            fired.append(True)
            raise _Timeout()
        signal.signal(signal.SIGALRM, alarm)
        if limit:
            signal.alarm(int(math.ceil(limit)))
        t = time.perf_counter()
        try:
            with open(os.devnull, "w") as devnull:
                old_out = os.dup(1)
                os.dup2(devnull.fileno(), 1)
                try:
                    rc = pytest.main(args)
                finally:
                    os.dup2(old_out, 1)
                    os.close(old_out)
            return ("timeout" if fired else int(rc)), time.perf_counter() - t
        except _Timeout:
            return "timeout", time.perf_counter() - t
        finally:
            signal.alarm(0)

    import proofs_checks  # noqa: F401  (load everything once)
    import proofs_checks._onn as onn

    rc, secs = run_tests()              # the baseline: no time limit (it builds the shared setups, under any load)
    if rc != 0:
        raise SystemExit(f"{check}: the unmutated tests fail (pytest exit {rc}): fix them first")
    # a mutant's limit from the baseline's time (the machine's load scales both), never below --timeout
    limit = max(timeout, 4 * secs)
    log(f"{check}: baseline {secs:.1f} s, {len(mutants)} mutant(s), time limit {limit:.0f} s each")
    originals = {}
    results = []
    for i, m in enumerate(mutants):
        mod = m["module"]
        if mod not in originals:
            originals[mod] = open(os.path.join(ROOT, "proofs_checks", f"{mod}.py")).read()
        _load(mod, m["source"])
        if mod in _SETUP_MODULES:
            onn._CACHE.clear()
        try:
            rc, secs = run_tests(limit)
        finally:
            _load(mod, originals[mod])
            if mod in _SETUP_MODULES:
                onn._CACHE.clear()
        status = "survived" if rc == 0 else ("timeout" if rc == "timeout" else "killed")
        results.append(dict({k: v for k, v in m.items() if k != "source"}, status=status, seconds=round(secs, 1)))
        log(f"{check}: [{i + 1}/{len(mutants)}] {status:8s} {mod}.{m['function']}:{m['line']} {m['what']}")
    return results


def all_mutants(check):
    return [m for mod, fn in TARGETS[check]["code"] for m in mutants_of(mod, fn)]


def sample_mutants(check, n):
    """A seeded sample of ``n`` mutants of ``check`` (all when n is 0 or there are fewer), then its slips."""
    import random
    import zlib

    muts = all_mutants(check)
    if n and len(muts) > n:
        rng = random.Random(zlib.crc32(check.encode()))
        muts = [muts[i] for i in sorted(rng.sample(range(len(muts)), n))]
    return muts + slip_mutants(check)


def _worker(check, timeout, out_path, sample):
    muts = sample_mutants(check, sample)
    res = run_check(check, muts, timeout, lambda s: print(s, file=sys.stderr, flush=True))
    with open(out_path, "w") as fh:
        json.dump(dict(results=res, population=len(all_mutants(check))), fh)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="append", help="check id (repeatable; default every check in TARGETS)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="least seconds per mutant before it counts as killed (the limit is max(this, 4 x baseline))")
    ap.add_argument("--out", default=os.path.join("gift-out", "mutation_pass.json"))
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--sample", type=int, default=24,
                    help="mutants per check, a seeded random sample (0: every mutant); the slips always run")
    ap.add_argument("--_worker", help=argparse.SUPPRESS)
    ap.add_argument("--_result", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a._worker:
        _worker(a._worker, a.timeout, a._result, a.sample)
        return 0
    checks = a.check or list(TARGETS)
    unknown = [c for c in checks if c not in TARGETS]
    if unknown:
        print(f"tools/mutation_pass.py: unknown check {unknown[0]!r}", file=sys.stderr)
        return 2
    if a.list:
        for c in checks:
            ms = sample_mutants(c, a.sample)
            print(f"{c}: {len(ms)} mutant(s) of {len(all_mutants(c))}")
            for m in ms:
                print(f"  {m['module']}.{m['function']}:{m['line']} {m['what']}")
        return 0
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    tmp = os.path.abspath(a.out) + ".parts"
    os.makedirs(tmp, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.setdefault("GIFT_TEST_SEED", "0")
    running, pending, results = [], list(checks), {}
    while pending or running:
        while pending and len(running) < a.jobs:
            c = pending.pop(0)
            part = os.path.join(tmp, f"{c.replace(' ', '_').replace('(', '').replace(')', '')}.json")
            p = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--_worker", c, "--_result", part,
                                  "--timeout", str(a.timeout), "--sample", str(a.sample)], env=env, cwd=ROOT)
            running.append((c, p, part))
        time.sleep(2)
        for c, p, part in list(running):
            if p.poll() is not None:
                running.remove((c, p, part))
                results[c] = json.load(open(part)) if p.returncode == 0 and os.path.exists(part) else None
    rows, table = {}, []
    width = max(len(c) for c in checks)
    table.append(f"{'check':<{width}}  killed/tried (of)  survivors")
    for c in checks:
        got = results.get(c)
        if got is None:
            table.append(f"{c:<{width}}  (worker failed)")
            continue
        r = got["results"]
        killed = sum(x["status"] != "survived" for x in r)
        surv = [f"{x['module']}.{x['function']}:{x['line']} {x['what']}" for x in r if x["status"] == "survived"]
        slips = [x for x in r if x.get("slip")]
        rows[c] = dict(killed=killed, tried=len(r), population=got["population"], survivors=surv,
                       slips=[dict(what=x["what"], status=x["status"]) for x in slips])
        table.append(f"{c:<{width}}  {killed:>4}/{len(r):<4} ({got['population']})  " + ("; ".join(surv) if surv else "-"))
    with open(a.out, "w") as fh:
        json.dump(rows, fh, indent=1)
    print("\n".join(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
