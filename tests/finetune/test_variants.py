"""Issue 25's variants of the fine-tuning methods, why GIFT returned w0 (``gift_info``), and the
ceiling of a line (the referee's best along w0 + a u)."""

import json
import math

import jax
import numpy as np
import pytest

import gift_theory as gt
from gift_theory.finetune import gift_printed, paired_line_search, referee, run_ceiling, run_finetune, why

from .test_finetune import _cli, _setup, axpy, norm, unit


def test_printed_with_w0_in_its_selection_returns_w0_at_the_optimum():
    """At w* = w0 every candidate is worse: as printed it returns one of them, with w0 among the
    candidates it returns w0 and says so."""
    for keep in (False, True):
        problem, u = _setup(0.0)
        w, info = gift_printed(problem, u, eta=0.05, keep_w0=keep)
        g = why("gift-printed", problem.w0, w, info)
        assert info["chosen_step"] == (0 if keep else info["chosen_step"]) and (info["chosen_step"] != 0) != keep
        assert g["kept_w0"] == keep and (("w0 among the candidates" in g["reason"]) == keep)
        assert problem.chip.true_loss(w) == problem.chip.true_loss(problem.w0) if keep else \
            problem.chip.true_loss(w) > problem.chip.true_loss(problem.w0)


def test_printed_with_w0_still_steps_when_a_step_is_better():
    problem, u = _setup(0.25)  # w* 5 steps along +u
    w, info = gift_printed(problem, u, eta=0.05, keep_w0=True)
    assert info["chosen_step"] == 1 and not why("gift-printed", problem.w0, w, info)["kept_w0"]


def test_gift_info_says_why_the_confirmation_kept_w0():
    """At the optimum with noise: either no measured step improved, or the confirmation ran and
    its z is below its boundary; the predicted gain is the fitted quadratic's at the best step."""
    reasons = set()
    for seed in range(6):
        problem, u = _setup(0.0, sigma=0.05, seed=seed)
        se = 0.05 ** 2 * 2 / np.sqrt(problem.K1)
        w, info = paired_line_search(problem, u, C2=2.0, se_pair=se)
        g = why("gift", problem.w0, w, info)
        assert g["kept_w0"] == (not info["accepted"])
        a = info["alpha_best"]
        assert g["predicted_gain"] == pytest.approx(a * info["C1"] - 0.5 * a * a * info["C2_fit"], rel=1e-12)
        assert g["predicted_gain_pct"] == pytest.approx(100 * g["predicted_gain"] / info["loss_w0"], rel=1e-12)
        if g["reason"].startswith("confirmation not significant"):
            assert g["confirmation_z"] <= info["z_look"] and f"{g['confirmation_z']:.2f}" in g["reason"]
        elif g["reason"].startswith("no measured step"):
            assert math.isnan(g["confirmation_z"]) and info["measured_gain"] <= 0
        else:
            assert g["reason"].startswith("accepted") and g["confirmation_z"] > info["z_look"]
        reasons.add(g["reason"].split(":")[0])
    assert reasons  # at least one kind of reason was seen


def test_without_confirmation_the_best_measured_step_is_taken_on_fewer_evaluations():
    problem, u = _setup(0.3, sigma=0.05, seed=3)
    se = 0.05 * 2 * 0.3 * np.sqrt(2) / np.sqrt(problem.K1)
    w, info = paired_line_search(problem, u, C2=2.0, se_pair=se, confirm=False)
    g = why("gift", problem.w0, w, info)
    assert not g["kept_w0"] and g["reason"].startswith("unconfirmed") and math.isnan(g["confirmation_z"])
    expect = axpy(info["alpha_best"], unit(u)[0], problem.w0)
    assert float(norm(axpy(-1.0, expect, w))) < 1e-6
    assert problem.evaluations_used() == 1 + len(info["alphas"])  # w0 once, one per measured step, no confirmation
    assert problem.chip.true_loss(w) < problem.chip.true_loss(problem.w0)


@pytest.fixture(scope="module")
def teacher_weights(tmp_path_factory):
    from gift_theory.training import save_weights

    path = str(tmp_path_factory.mktemp("w") / "w.npz")
    save_weights(path, gt.init_params(jax.random.PRNGKey(0), gt.Architecture((4, 3, 2))), {})
    return path


@pytest.mark.slow
def test_run_finetune_reports_gift_info_and_the_retrain_control(teacher_weights):
    common = dict(dataset="teacher", arch="4-3-2", s0=0.05, st=0.2, seed=0, weights=teacher_weights, budget=6,
                  K1=200, referee_K2=4)
    r = run_finetune(method="gift", **common)
    assert set(r["gift_info"]) == {"kept_w0", "reason", "confirmation_z", "predicted_gain", "predicted_gain_pct"}
    assert r["gift_info"]["kept_w0"] == (r["loss_after"] == r["loss_before"] and not r["info"]["accepted"])
    assert run_finetune(method="spsa", **common)["gift_info"] is None
    oracle = run_finetune(method="retrain", **common)
    control = run_finetune(method="retrain", at="s0", **common)
    assert oracle["info"]["physics"] == "awgn(s=0.2)" and control["info"]["physics"] == "awgn(s=0.05)"
    assert oracle["loss_before"] == control["loss_before"] and oracle["loss_after"] != control["loss_after"]
    with pytest.raises(gt.GiftInputError, match="at="):
        run_finetune(method="retrain", at="nowhere", **common)


def test_finetune_command_json_carries_gift_info_and_the_variant_flags(capsys, teacher_weights):
    base = ["finetune", "--dataset", "teacher", "--arch", "4-3-2", "--s0", "0.05", "--st", "0.2", "--budget", "5",
            "--K1", "200", "--weights", teacher_weights, "--json"]
    rc, out, err = _cli(capsys, *base, "--method", "gift-printed", "--keep-w0", "--eta-pct", "0.1")
    assert rc == 0, err
    r = json.loads(out)  # strict JSON: no NaN
    assert set(r["gift_info"]) >= {"kept_w0", "reason", "confirmation_z", "predicted_gain"}
    assert r["gift_info"]["confirmation_z"] is None  # Algorithm 1 has no confirmation
    assert r["info"]["keep_w0"] is True and r["info"]["rel_step"] == pytest.approx(0.001, rel=1e-5)
    rc, out, err = _cli(capsys, *base, "--method", "spsa", "--keep-w0")
    assert rc == 2 and out == "" and "--keep-w0" in err and len(err.strip().splitlines()) == 1


def test_the_ceiling_is_the_referees_best_along_the_line_and_its_numbers_are_the_referees():
    """Validated against the referee itself: w0's numbers and the chosen step's are what
    ``referee`` gives at those weights, and no scanned step beats the chosen one on the scan."""
    from gift_theory.data import load_dataset
    from gift_theory.finetune import direction, load_setting, make_problem, true_physics

    kw = dict(dataset="teacher", arch="4-3-2", s0=0.05, st=0.2, seed=1)
    c = run_ceiling(**kw, kinds=("pathwise", "gradient"), referee_K2=4, scan_K2=2, n_side=6, refine=3)
    ds = load_dataset("teacher")
    _, arch, w0 = load_setting("teacher", "4-3-2", 0.05, 1, progress=False)
    phys = true_physics(0.2)
    before = referee(w0, ds.x_train, ds.y_train, ds.labels_train, phys, arch, K2=4)
    assert c["loss_before"] == pytest.approx(before["loss"], rel=1e-6)
    assert c["accuracy_before"] == pytest.approx(before["accuracy"], rel=1e-6)
    problem = make_problem(arch, w0, ds.x_train, ds.y_train, s0=0.05, true_physics=phys, budget=0, seed=1)
    for kind in ("pathwise", "gradient"):
        u, _ = unit(direction(problem, kind, K2=16)[0])
        w = axpy(c[f"{kind}_rel_step_loss"] * c["w0_norm"], u, w0)
        at = referee(w, ds.x_train, ds.y_train, ds.labels_train, phys, arch, K2=4)
        test = referee(w, ds.x_test, ds.y_test, ds.labels_test, phys, arch, K2=4)
        assert c[f"{kind}_loss"] == pytest.approx(at["loss"], rel=1e-5)
        assert c[f"{kind}_test_accuracy"] == pytest.approx(test["accuracy"], rel=1e-5)
        scan = c["scan"][kind]
        i = int(np.argmin(scan["loss"]))
        assert scan["rel_step"][i] == c[f"{kind}_rel_step_loss"] and 0.0 in scan["rel_step"]
        assert c[f"{kind}_scan_points"] == len(scan["rel_step"]) >= 13
    assert -1 <= c["cos_pathwise_gradient"] <= 1
