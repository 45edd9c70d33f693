"""Bad input gets one clear line and exit status 2, never a traceback; parsers never crash."""

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

import gift_theory as gt
from gift_theory.cli._main import main


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
