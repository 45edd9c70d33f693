"""Bad input gets one clear line and exit status 2, never a traceback; parsers never crash."""

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

import gift_theory as gt
from gift_theory.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("argv,fragment", [
    (["train", "--s0", "-0.1"], "--s0"),
    (["train", "--arch", "64-0-10"], "positive"),
    (["train", "--arch", "64-abc-10"], "--arch"),
    (["train", "--arch", "60-10"], "does not fit"),
    (["train", "--dataset", "mnist", "--data-folder", "/no/such/folder"], "/no/such/folder"),
    (["train", "--dataset", "nope"], "--dataset"),
    (["train", "--seed", "-3"], "--seed"),
    (["train", "--lr", "0"], "--lr"),
    (["frobnicate"], "unknown command"),
    (["demo", "--dataset", "mnist"], "--data-folder"),
    (["demo", "--dataset", "mnist", "--data-folder", "/no/such/folder", "--parts", "finetune"], "/no/such/folder"),
    (["demo", "--seed", "-1"], "must be an integer >= 0"),
    (["train", "--seed", "-1"], "must be an integer >= 0"),
    (["demo", "--s0", "0"], "must be a finite number > 0"),
    (["demo", "--budget", "nan"], "must be a finite number"),
    (["finetune", "--s0", "0", "--st", "0.2"], "must be a finite number > 0"),
    (["finetune", "--s0", "0.1", "--st", "0.2", "--seed", "-1"], "must be an integer >= 0"),
    (["finetune", "--s0", "0.1", "--st", "0.2", "--dataset", "mnist"], "--data-folder"),
    (["train", "--dataset", "digits", "--data-folder", "/tmp"], "only --dataset mnist"),
])
def test_bad_arguments_give_one_line_and_exit_2(capsys, argv, fragment):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in err


def test_help_lists_every_contract_command(capsys):
    code, out, _ = run(capsys, "--help")
    assert code == 0
    for name in ("demo", "finetune", "bench", "check", "diagnose", "fit", "simulate", "compare", "train"):
        assert name in out


@pytest.mark.slow
def test_train_json_is_one_object(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("GIFT_CACHE_DIR", str(tmp_path))
    code, out, err = run(capsys, "train", "--dataset", "teacher", "--arch", "4-3-2", "--epochs", "1", "--json")
    assert code == 0
    obj = json.loads(out)
    assert obj["arch"] == "4-3-2" and obj["cached"] is False and 0 <= obj["test_accuracy"] <= 1
    code, out, _ = run(capsys, "train", "--dataset", "teacher", "--arch", "4-3-2", "--epochs", "1", "--json")
    assert json.loads(out)["cached"] is True


@given(text=st.text(max_size=30))
def test_architecture_parser_never_crashes(text):
    try:
        arch = gt.Architecture.parse(text)
    except gt.GiftInputError as exc:
        assert "\n" not in str(exc)
    else:
        assert all(w >= 1 for w in arch.widths) and len(arch.widths) >= 2


@given(text=st.text(alphabet=st.sampled_from(list("abcdeilmnopqrstuvwxyz_=,:.-0123456789 ")), max_size=30)
       | st.sampled_from(["shot=0.01", "quantization=6,1", "quantization=bits:6,v_range:1", "laplace",
                          "awgn=-1", "crosstalk=nan", "shot", "quantization=6"]))
def test_effect_spec_parser_never_crashes(text):
    try:
        e = gt.parse_effect(text)
    except gt.GiftInputError as exc:
        assert "\n" not in str(exc)
    else:
        assert e.name in gt.effects.REGISTRY  # the built-in effects and any loaded plugin
        e.validate()


@pytest.mark.parametrize("spec,fragment", [("awgn=-1", "outside"), ("blur=2", "unknown effect"),
                                           ("shot=abc", "not a number"), ("quantization=1,2,3", "takes 2"),
                                           ("saturation=0", "outside")])
def test_effect_spec_errors(spec, fragment):
    with pytest.raises(gt.GiftInputError, match=fragment):
        gt.parse_effect(spec)


def test_physics_composition_errors():
    with pytest.raises(gt.GiftInputError, match="exclude"):
        gt.Physics.parse(["laplace", "uniform"], s=0.1)
    with pytest.raises(gt.GiftInputError, match="twice"):
        gt.Physics.parse(["shot=0.1", "shot=0.2"])
    with pytest.raises(gt.GiftInputError, match="no effect"):
        gt.awgn(0.1).replace(q=0.1)


@pytest.mark.parametrize("argv,suggestion", [
    (["demp"], "did you mean 'demo'?"),
    (["demo", "--parts", "finetun"], "did you mean 'finetune'?"),
    (["train", "--dataset", "mnst"], "did you mean 'mnist'?"),
    (["finetune", "--s0", "0.1", "--st", "0.2", "--true-effect", "shto=0.1"], "did you mean 'shot'?"),
])
def test_unknown_names_get_a_did_you_mean(capsys, argv, suggestion):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert suggestion in err


def test_did_you_mean_says_nothing_when_nothing_is_close():
    from gift_theory.cli import did_you_mean

    msg = "gift: unknown command 'zzzz'; commands: demo, train"
    assert did_you_mean(msg) == msg


def _commands():
    # private: the registry of every command, core and registered, to parametrise over
    from gift_theory.cli._main import commands

    return list(commands())


@pytest.mark.parametrize("command", _commands())
def test_every_flag_has_help_and_help_points_to_the_reference_page(capsys, command):
    # private: the parser each command fills, read flag by flag
    from gift_theory.cli._main import _Parser, command_module

    parser = _Parser(prog=f"gift {command}")
    command_module(command).add_arguments(parser)
    missing = [a.option_strings or a.dest for a in parser._actions if not a.help]
    assert not missing, f"gift {command}: flags without help: {missing}"
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = capsys.readouterr().out
    assert "docs/reference.md" in out and "CONTRACTS" not in out


def test_progress_counts_items_with_time_left_and_is_silent_when_quiet():
    import io

    from gift_theory.cli import Progress

    buf = io.StringIO()
    p = Progress("gift x", stream=buf)
    for i in range(3):
        p(i, 3, f"item{i}")
    lines = buf.getvalue().splitlines()
    assert [ln.split("]")[0] for ln in lines] == ["gift x: [1/3", "gift x: [2/3", "gift x: [3/3"]
    assert "left" not in lines[0] and all("s left" in ln for ln in lines[1:])
    quiet = io.StringIO()
    q = Progress("gift x", quiet=True, stream=quiet)
    q(0, 2, "a")
    q(1, 2, "b")
    assert quiet.getvalue() == ""


def test_progress_reported_as_items_finish_estimates_what_is_left(monkeypatch):
    """Items of 1 s each, reported as each is done (the diagnosis's candidates): after item k of n,
    (n - k) s are left; counting the finished item as still to run said ~3 s left after the last."""
    import io

    import time

    from gift_theory.cli import Progress

    clock = iter(range(100))
    monkeypatch.setattr(time, "perf_counter", lambda: float(next(clock)))
    buf = io.StringIO()
    p = Progress("gift x", stream=buf, after=True)
    for i in range(4):
        p(i, 4, f"item{i}: done")
    lines = buf.getvalue().splitlines()
    assert [ln.split("(")[1] for ln in lines] == ["0 s)", "1 s, ~2 s left)", "2 s, ~1 s left)", "3 s)"]


@pytest.mark.slow
def test_import_gift_theory_changes_no_jax_setting():
    import subprocess
    import sys

    code = ("import jax; before = dict(jax.config.values); import gift_theory, gift_theory.lab, gift_theory.finetune; "
            "after = dict(jax.config.values); print(sorted(k for k in after if after[k] != before.get(k)))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "[]"


def _demo_result():
    evidence = ("a long evidence string " * 12).strip() + " ends with its number 0.123"
    row = {"method": "gift", "loss_before": 0.7, "loss_after": 0.7, "accuracy_before": 0.9, "accuracy_after": 0.9,
           "test_accuracy_after": 0.9, "in_situ_evaluations": 19, "seconds": 1.0, "oracle_fraction": 0.0,
           "why": {"kept_w0": True, "reason": "confirmation not significant: z = 1.84 <= 3.13 after 7 fresh pairs",
                   "confirmation_z": 1.84, "predicted_gain": 0.0123}}
    return {"mode": "pair", "dataset": "digits", "arch": "64-32-32-10", "s0": 0.05, "st": 0.2, "true_effects": [],
            "budget": 20, "rows": [row, dict(row, method="retrain", why=None, loss_after=0.6, oracle_fraction=1.0)],
            "theory": {"checks": [{"id": "x", "verdict": "fails", "evidence": evidence,
                                   "correction": "printed rhs / true d/ds grad J = 0.5"}], "total_checks": 21},
            "seconds": 3.0}, evidence


def test_demo_text_prints_evidence_whole_says_why_gift_kept_w0_and_counts_checks_from_the_result():
    from gift_theory.cli._demo import render  # private: the text for a given result, without running the demo (minutes)

    result, evidence = _demo_result()
    text = render(result)
    flat = " ".join(text.split())
    assert evidence in flat and "printed rhs / true d/ds grad J = 0.5" in flat
    gift_row = [ln for ln in text.splitlines() if ln.startswith("gift ")][0]
    assert "kept w0" in gift_row and "z = 1.84" in gift_row and "predicted gain 0.0123" in gift_row
    assert "gift check runs all 21" in text and "twelve" not in text


@pytest.mark.slow
def test_demo_theory_part_counts_the_registry():
    from proofs_checks import CHECK_IDS

    from gift_theory.cli._main import command_module  # private: the demo's theory part of a registered command, alone

    out = command_module("check").demo_part(ids=("score_function_identity",))
    assert out["total_checks"] == len(CHECK_IDS) and [c["id"] for c in out["checks"]] == ["score_function_identity"]


def test_reference_page_lists_every_builtin_effect_with_its_mechanism_class():
    """docs/reference.md (the page --help points to) against the registry, not against a list."""
    import os
    import re

    from gift_theory.effects import BUILTIN, MECHANISMS, REGISTRY

    path = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "reference.md")
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    rows = {m.group(1): m.group(2).strip() for m in re.finditer(r"^\| `(\w+)` \|[^\n]*\| (\w+) \|$", text, re.M)}
    for name in BUILTIN:
        assert rows.get(name) == REGISTRY[name].mechanism, name
    classes = set(re.findall(r"^\| `(\w+)` \| [^|]+ \| [^|]*\|$", text.split("## §6")[1], re.M))
    assert classes == set(MECHANISMS)


def _tiny_mnist(folder, n_train=64, n_test=16):
    import numpy as np

    from gift_theory.data import write_idx

    rng = np.random.default_rng(0)
    for prefix, n in (("train", n_train), ("t10k", n_test)):  # MNIST's own file names
        write_idx(str(folder / f"{prefix}-images-idx3-ubyte"), rng.integers(0, 256, (n, 28, 28), dtype=np.uint8))
        write_idx(str(folder / f"{prefix}-labels-idx1-ubyte"), (np.arange(n) % 10).astype(np.uint8))


@pytest.mark.slow
def test_finetune_reads_mnist_from_the_data_folder(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("GIFT_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "mnist").mkdir()
    _tiny_mnist(tmp_path / "mnist")
    code, out, err = run(capsys, "finetune", "--dataset", "mnist", "--data-folder", str(tmp_path / "mnist"),
                         "--arch", "784-4-10", "--s0", "0.1", "--st", "0.2", "--method", "none", "--json")
    assert code == 0, err
    obj = json.loads(out)
    assert obj["dataset"] == "mnist" and obj["arch"] == [784, 4, 10] and obj["loss_after"] == obj["loss_before"]


@pytest.mark.slow
def test_the_line_s_ceiling_reads_mnist_from_the_data_folder(tmp_path, monkeypatch):
    """run_ceiling takes the IDX folder as run_finetune does, so the ceiling sweeps run on full MNIST."""
    from gift_theory.finetune import run_ceiling

    monkeypatch.setenv("GIFT_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "mnist").mkdir()
    _tiny_mnist(tmp_path / "mnist")
    res = run_ceiling(dataset="mnist", arch="784-4-10", s0=0.1, st=0.2, kinds=("pathwise",), train_epochs=1,
                      data_folder=str(tmp_path / "mnist"), direction_K2=2, n_side=2, refine=0, scan_K2=1,
                      referee_K2=2)
    assert res["dataset"] == "mnist" and res["arch"] == [784, 4, 10]
    assert 0.0 <= res["pathwise_accuracy"] <= 1.0 and 0.0 <= res["accuracy_before"] <= 1.0
    with pytest.raises(gt.GiftInputError, match="nowhere: no such folder"):
        run_ceiling(dataset="mnist", arch="784-4-10", s0=0.1, st=0.2, kinds=("pathwise",), train_epochs=1,
                    data_folder=str(tmp_path / "nowhere"))


def test_gift_theory_never_imports_the_packages_on_top():
    """proofs_checks and paper_figures register their commands (entry-point group gift.commands);
    no module of gift_theory names them in an import."""
    import ast
    import os
    from importlib.metadata import entry_points

    root = os.path.dirname(gt.__file__)
    upward = []
    for folder, _, files in os.walk(root):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                with open(path, encoding="utf-8") as fh:
                    tree = ast.parse(fh.read())
                for node in ast.walk(tree):
                    names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                             [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
                    upward += [f"{path}:{node.lineno} {n}" for n in names
                               if n.split(".")[0] in ("proofs_checks", "paper_figures", "studies", "linear_case")]
    assert not upward, upward
    registered = {ep.name for ep in entry_points(group="gift.commands")}
    assert {"check", "figures"} <= registered, "pip install -e . registers the gift.commands entry points"


def test_finetune_text_says_what_identify_retrain_identified():
    from gift_theory.cli._finetune import render  # private: the text for a given result, without a fine-tuning run

    r = {"dataset": "digits", "arch": [64, 16, 10], "s0": 0.05, "st": 0.2, "method": "identify-retrain",
         **{k: 1.0 for k in ("loss_before", "loss_after", "accuracy_before", "accuracy_after", "test_loss_before",
                             "test_loss_after", "test_accuracy_before", "test_accuracy_after", "seconds")},
         "in_situ_evaluations": 2, "gift_info": None,
         "info": {"physics": "awgn(s=0.19) + shot(q=0.01)", "inputs": 50, "shots": 16, "taps": True,
                  "baseline_p": 1e-9, "missing_effect_detected": True, "ranking": ["shot", "multiplicative"]}}
    last = render(r).splitlines()[-1]
    assert "awgn(s=0.19) + shot(q=0.01)" in last and "50 inputs x 16 shots" in last and "shot, multiplicative" in last


def test_training_on_a_few_mnist_images_says_so():
    from gift_theory.cli._train import render  # private: the text for given results, without training

    r = {"dataset": "mnist", "arch": "784-4-10", "s0": 0.1, "seed": 0, "cached": False, "train_seconds": 1.0,
         "train_loss": 1.0, "train_accuracy": 0.5, "test_loss": 1.0, "test_accuracy": 0.5, "path": "w.npz",
         "train_examples": 10, "test_examples": 10}
    text = render(r)
    assert "10 training / 10 test examples" in text and "not MNIST's 60000" in text
    assert "not MNIST's" not in render(dict(r, train_examples=60000, test_examples=10000))
    assert "not MNIST's" not in render(dict(r, dataset="digits"))
