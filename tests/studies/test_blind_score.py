"""The blind studies' scorer on hand-written ``gift diagnose --json`` objects (no gift run).

The scorer must read only the label and CONTRACTS §4/§6 fields, score each column by its
stated rule, and report a field the JSON lacks as missing (None), never crash.
"""

import json

import numpy as np
import pytest

from studies import blind
from studies.contract_sim import OPEN_PHYSICS


def _out(detected=True, ranking=(("weight_error", 0.3),), explained=None, failing=None, mechanisms=None,
         where=None, omit=()):
    out = {"baseline": {"effects": ["awgn"], "params": {"s": 0.1}, "discrepancy": 9.0, "noise_floor": 1.0,
                        "p_value": 1e-9 if detected else 0.4},
           "missing_effect_detected": detected,
           "ranking": [dict({"effect": e.split("+")[-1], "discrepancy_after": 1.0, "p_value_after": p, "params": {}},
                            **({"with": e.split("+")[:-1]} if "+" in e else {})) for e, p in ranking],
           "explained": explained, "failing_layers": failing,
           "mechanisms": None if mechanisms is None else [{"mechanism": m, "layers": [1], "score": 5.0,
                                                           "evidence": "hand-written"} for m in mechanisms]}
    if where is not None:
        out["where"] = [{"layer": l, "discrepancy": 1.0, "z": 0.0, "p_value": p} for l, p in where.items()]
    for k in omit:
        out.pop(k)
    return out


def _label(name, L=3):
    spec = OPEN_PHYSICS.get(name)
    return {"physics": name, "mechanism": spec.mechanism if spec else None, "layers": spec.layers(L) if spec else [],
            "expressible_by": list(spec.expressible_by) if spec else []}


def test_a_right_explanation_with_the_right_layers_and_class():
    row = blind.score_row(_out(ranking=[("bias_offset", 0.3), ("weight_error", 1e-5)], explained=True,
                               failing=[3, 1, 2], mechanisms=["bias_offset", "weight_error"]),
                          _label("bias_offset"), taps=True)
    assert row["detected"] and row["explained"] is True
    assert row["explained_correct"] and row["expressible_top"] and not row["wrong_explanation"]
    assert row["failing_layers_exact"] and row["mechanism_first"]


def test_an_effect_outside_the_catalogue_presented_as_explained_is_a_wrong_explanation():
    row = blind.score_row(_out(ranking=[("weight_error", 0.42)], explained=True, failing=[1],
                               mechanisms=["weight_error", "activation_mismatch"]),
                          _label("activation_shape"), taps=True)
    assert row["explained_correct"] is False and row["wrong_explanation"] is True
    assert row["wrong_by_baseline"] is False and row["expressible_top"] is None
    assert row["failing_layers_exact"] is False          # the label says layers 1 and 2
    assert row["mechanism_first"] is False


def test_an_honest_no_on_physics_outside_the_catalogue():
    row = blind.score_row(_out(ranking=[("saturation", 1e-40)], explained=False, failing=[3],
                               mechanisms=["readout_nonlinearity"]), _label("square_law"), taps=True)
    assert row["explained_correct"] is True and row["wrong_explanation"] is False
    assert row["failing_layers_exact"] and row["mechanism_first"]


def test_a_missed_detection_counts_as_a_wrong_explanation_by_the_baseline():
    row = blind.score_row(_out(detected=False, explained=True, failing=[], mechanisms=[]),
                          _label("signal_noise"), taps=True)
    assert row["wrong_explanation"] is True and row["wrong_by_baseline"] is True
    assert row["mechanism_first"] is False and row["failing_layers_exact"] is False


def test_pairs_are_named_by_their_sorted_effects():
    lab = {"physics": "shot+crosstalk", "mechanism": "input_dependent_noise+weight_error",
           "classes": ["input_dependent_noise", "weight_error"], "layers": [1, 2],
           "expressible_by": ["crosstalk+shot"]}
    row = blind.score_row(_out(ranking=[("crosstalk+shot", 0.2)], explained=True, failing=[1, 2],
                               mechanisms=["weight_error"]), lab, taps=True)
    assert row["explained_correct"] and row["mechanism_first"] and row["first_entry"] == ["crosstalk", "shot"]
    assert blind._identified(row, lab)


def test_null_files():
    ok = blind.score_row(_out(detected=False, explained=True, failing=[], mechanisms=[]), _label("none"), taps=True)
    assert ok["explained_correct"] and not ok["wrong_explanation"] and ok["failing_layers_exact"]
    assert ok["mechanism_first"] is None
    alarm = blind.score_row(_out(detected=True, explained=True, failing=[2], mechanisms=["noise_law"]),
                            _label("none"), taps=True)
    assert alarm["explained_correct"] is False and alarm["wrong_explanation"] is True
    assert alarm["wrong_by_baseline"] is False and alarm["failing_layers_exact"] is False


def test_fields_the_json_lacks_are_missing_not_a_crash():
    old = _out(ranking=[("weight_error", 0.42)], where={1: 1e-9, 2: 0.3}, omit=("explained", "failing_layers",
                                                                               "mechanisms"))
    row = blind.score_row(old, _label("activation_gain", L=2), taps=True)
    for key in ("explained", "explained_correct", "wrong_explanation", "wrong_by_baseline", "failing_layers",
                "failing_layers_exact", "mechanisms", "mechanism_first"):
        assert row[key] is None, key
    assert row["expressible_top"] is False and row["one_step_p"] == {1: 1e-9, 2: 0.3}
    assert row["one_step_layers_exact"] is True           # layer 1 below 0.01 / 2, layer 2 above: the hidden layer
    near = blind.score_row(_out(where={1: 0.007, 2: 0.3}), _label("activation_gain", L=2), taps=True)
    assert near["one_step_layers_exact"] is False         # 0.007 > 0.01 / 2 is not a failure after Bonferroni
    assert blind.score_row(_out(where={1: 1e-9}), _label("activation_gain", L=2), taps=False)["one_step_layers_exact"] is None
    summary = blind.summarize([dict(row, physics="activation_gain", file="a.npz")], builtin=False)
    counts = summary["per_physics"]["activation_gain"]
    assert counts["explained_correct"] is None and counts["detected"] == 1 and summary["wrong_explanations"] is None


def test_without_taps_failing_layers_are_not_scored():
    row = blind.score_row(_out(explained=False, failing=None, mechanisms=["activation_mismatch"]),
                          _label("activation_gain"), taps=False)
    assert row["failing_layers_exact"] is None and row["mechanism_first"] is True


def test_the_summary_counts_per_physics_and_wrong_explanations():
    rows = [dict(blind.score_row(_out(ranking=[(top, 0.5)], explained=expl, failing=[1, 2],
                                      mechanisms=["activation_mismatch"]), _label(name), taps=True),
                 physics=name, file=f"{name}_{i}.npz")
            for i, (name, top, expl) in enumerate([("activation_gain", "activation_gain", True),
                                                    ("activation_gain", "weight_error", True),
                                                    ("activation_shape", "weight_error", False),
                                                    ("activation_shape", "weight_error", True)])]
    rows.append({"physics": "activation_shape", "file": "broken.npz", "error": "gift diagnose exit 1"})
    s = blind.summarize(rows, builtin=False)
    assert s["per_physics"]["activation_gain"]["explained_correct"] == 1
    assert s["per_physics"]["activation_gain"]["wrong_explanation"] == 1
    assert s["per_physics"]["activation_shape"] == {**s["per_physics"]["activation_shape"], "files": 2, "errors": 1,
                                                   "wrong_explanation": 1, "explained_correct": 1}
    assert s["wrong_explanations"] == 2 and s["errors"] == 1
    assert s["per_physics"]["activation_gain"]["failing_layers_exact"] == 2


def test_open_files_carry_no_label_and_the_sidecar_does(tmp_path):
    names = blind.write_open(str(tmp_path), 1, seed=3, taps=True, physics=("bias_offset", "square_law"), nulls=1,
                             setting="reference")
    labels = json.loads((tmp_path / "labels.json").read_text())
    assert sorted(labels) == names == ["bias_offset_0.npz", "none_0.npz", "square_law_0.npz"]
    for f in names:
        with np.load(tmp_path / f) as z:
            assert set(z.files) == {"x", "y", "t", "activation", "W1", "W2", "W3", "b1", "b2", "b3", "a1", "a2"}
            assert z["y"].shape == (160, 48, 4)
    assert labels["square_law_0.npz"]["layers"] == [3] and labels["square_law_0.npz"]["mechanism"] == "readout_nonlinearity"
    assert labels["bias_offset_0.npz"]["expressible_by"] == ["bias_offset"]
    assert [len(d) for d in labels["bias_offset_0.npz"]["params"]["delta"]] == [16, 8, 4]
    with np.load(tmp_path / "square_law_0.npz") as z:
        assert (z["y"] >= 0).all()  # an intensity


def test_bad_input_is_one_line_and_status_2(tmp_path, capsys):
    assert blind.main(["score", str(tmp_path / "nowhere")]) == 2
    assert blind.main(["write", str(tmp_path / "w"), "--physics", "open", "--only", "bogus"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no such folder" in err[0] and "bogus" in err[1]


@pytest.mark.parametrize("name", sorted(OPEN_PHYSICS))
def test_every_open_physics_declares_a_contract_class_and_catalogue_names(name):
    from studies.contract_sim import CATALOGUE, MECHANISMS

    spec = OPEN_PHYSICS[name]
    assert spec.mechanism in MECHANISMS and set(spec.classes()) <= set(MECHANISMS)
    assert set(spec.expressible_by) <= set(CATALOGUE) | {"bias_offset", "activation_gain"}
    assert set(spec.contained_in) <= set(CATALOGUE)
    layers = spec.layers(4, spec.draw(np.random.default_rng(0), (5, 7, 6, 4, 3), 10, 2))
    assert layers and set(layers) <= {1, 2, 3, 4}


def test_builtin_labels_come_from_the_file(tmp_path):
    (path,) = blind.write(str(tmp_path), 1, seed=2, taps=False, effects=("shot+crosstalk",))
    label = blind.builtin_label(path)
    L = len(blind._shape(path)["arch"]) - 1
    assert label["physics"] == "shot+crosstalk" and label["expressible_by"] == ["crosstalk+shot"]
    assert label["classes"] == ["input_dependent_noise", "weight_error"] and label["layers"] == list(range(1, L + 1))
    assert set(label["truth"]) == {"s", "shot", "crosstalk"}


def test_score_loop_seeds_labels_match_and_errors(tmp_path, monkeypatch):
    """The loop with a stand-in for gift: file i (sorted) gets --seed i, also under --match; a
    failed diagnose is a row with its error line; the summary is the last line."""
    import io

    blind.write_open(str(tmp_path), 1, seed=4, taps=False, physics=("square_law", "activation_gain"), nulls=1,
                     setting="reference")
    seen = []

    def fake(path, seed, runner):
        seen.append((path.rsplit("/", 1)[-1], seed))
        if "none" in path:
            return None, "gift diagnose exit 1: boom"
        return _out(ranking=[("activation_gain", 0.5)], explained=True, failing=None,
                    mechanisms=["activation_mismatch"]), None

    monkeypatch.setattr(blind, "run_diagnose", fake)
    buf = io.StringIO()
    s = blind.score(str(tmp_path), out=buf)
    lines = [json.loads(x) for x in buf.getvalue().splitlines()]
    assert seen == [("activation_gain_0.npz", 0), ("none_0.npz", 1), ("square_law_0.npz", 2)]
    assert lines[-1] == s and s["errors"] == 1 and lines[1]["error"].endswith("boom")
    assert lines[0]["explained_correct"] and lines[0]["mechanism_first"] and lines[0]["failing_layers_exact"] is None
    assert lines[2]["wrong_explanation"] and s["wrong_explanations"] == 1
    seen.clear()
    blind.score(str(tmp_path), out=io.StringIO(), match="square")
    assert seen == [("square_law_0.npz", 2)]


def test_a_rejected_effect_first_is_counted_with_status_or_p_values():
    """Without ``status``: ranking[0] below 0.01 while another entry is at or above it; with it:
    ranking[0] "fails" while another "passes" or is "refused" (CONTRACTS §6's ordering rule)."""
    lab = _label("activation_gain")
    assert blind.score_row(_out(ranking=[("drift", 1e-40), ("weight_error", 0.3)]), lab, taps=True)["rejected_first"]
    assert not blind.score_row(_out(ranking=[("drift", 1e-40), ("weight_error", 1e-9)]), lab,
                               taps=True)["rejected_first"]
    assert not blind.score_row(_out(ranking=[("weight_error", 0.3), ("drift", 1e-40)]), lab,
                               taps=True)["rejected_first"]
    out = _out(ranking=[("drift", 1e-40), ("weight_error", 0.3)])
    out["ranking"][0]["status"], out["ranking"][1]["status"] = "fails", "refused"
    row = blind.score_row(out, lab, taps=True)
    assert row["rejected_first"] and row["status_first"] == "fails"
    out["ranking"][1]["status"] = "fails"                  # the status rule wins over the p-values
    assert blind.score_row(out, lab, taps=True)["rejected_first"] is False
    assert blind.score_row(_out(ranking=()), lab, taps=True)["rejected_first"] is None


def test_rescore_and_table_read_kept_answers(tmp_path, capsys):
    """rescore scores kept diagnose JSONs with no gift run; table prints one row per file and the set's counts."""
    import io

    folder = tmp_path / "study"
    blind.write_open(str(folder), 1, seed=4, taps=True, physics=("square_law",), nulls=1, setting="reference")
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "square_law_0.json").write_text(json.dumps(_out(ranking=[("saturation", 1e-40), ("shot", 0.2)],
                                                            explained=False, failing=[3],
                                                            mechanisms=["readout_nonlinearity"])))
    buf = io.StringIO()
    summary = blind.rescore(str(folder), str(kept), out=buf)
    assert summary["errors"] == 1 and summary["rejected_first"] == 1 and summary["mechanism_first"] == 1
    path = tmp_path / "rows.jsonl"
    path.write_text(buf.getvalue())
    blind.table([str(path)])
    text = capsys.readouterr().out
    assert "| square_law_0.npz | readout_nonlinearity; [3] | yes" in text
    assert "| rows.jsonl | 1 (+1 errors) | 1/1 | - | 0/1 | 1/1 | 1/1 | 1/1 |" in text
