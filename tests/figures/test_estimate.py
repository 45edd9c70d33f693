"""The paper-scale estimate from measured point files: steady seconds per point, shared
in-silico work charged once per (net, method, s0, seed), trainings and compiling."""

import pytest

from paper_figures import _sweep
from paper_figures._scales import sweeps
from paper_figures.estimate import estimate, main

STEADY, SHARED, TRAIN, LOAD, COMPILE = 10.0, 4.0, 30.0, 0.5, 7.0


def _write(folder, *, hits_only=("random",)):
    """Fake point files of the tiny scale: every point STEADY s; the first point of each group
    computes SHARED s of shared work (but methods in ``hits_only`` find it done); the first
    point of each (net, s0, seed) trains (TRAIN s), the others load (LOAD s); one point compiles."""
    seen_group, seen_net, first = set(), set(), True
    for name, sw in sweeps("tiny").items():
        for p in sw.points():
            if name == "estimators":
                res, secs = {"rel_error": 0.1}, 1.0
            else:
                method = p.get("method", sw.fixed.get("method"))
                group = (sw.fixed["net"], method, p["s0"], p["seed"])
                net = (sw.fixed["net"], p["s0"], p["seed"])
                miss = group not in seen_group and method not in hits_only
                seen_group.add(group)
                setting = TRAIN + LOAD if net not in seen_net else LOAD
                seen_net.add(net)
                res = {"seconds_setting": setting, "seconds_compiling": COMPILE if first else 0.0,
                       "seconds_shared": SHARED if miss else 0.0, "shared_misses": 4 if miss else 0,
                       "shared_hits": 0 if miss else 4}
                secs = STEADY + res["seconds_setting"] + res["seconds_compiling"] + res["seconds_shared"]
                first = False
            _sweep._persist(str(folder), sw, p, {"result": res, "seconds": secs})


def test_the_estimate_charges_each_part_once(tmp_path):
    _write(tmp_path)
    r = estimate(str(tmp_path), target="tiny", source="tiny", workers=2)
    sws = sweeps("tiny")
    gift_points = sum(sw.size for n, sw in sws.items() if n != "estimators")
    groups = {(sw.fixed["net"], p.get("method", sw.fixed.get("method")), p["s0"], p["seed"])
              for n, sw in sws.items() if n != "estimators" for p in sw.points()}
    charged = [g for g in groups if g[1] != "random"]
    assert r["shared_found_done"] == ["shallow:random"]
    assert r["shared_seconds"] == pytest.approx(SHARED * len(charged))
    assert sum(s["seconds"] for s in r["sweeps"] if s["sweep"] != "estimators") == pytest.approx(STEADY * gift_points)
    assert all(v == pytest.approx(TRAIN) for v in r["training_seconds_per_net"].values())
    assert r["compile_seconds_per_worker"] == pytest.approx(COMPILE)
    expected = STEADY * gift_points + SHARED * len(charged) + r["training_seconds"] + 2 * COMPILE \
        + sws["estimators"].size * 1.0
    assert r["work_seconds"] == pytest.approx(expected)
    assert r["wall_hours"] == pytest.approx(expected / 2 / 3600)


def test_trainings_can_come_from_another_run(tmp_path):
    _write(tmp_path / "trained")
    _write(tmp_path / "cached")
    # a run on cached weights: every setting is a load
    for path in (tmp_path / "cached").rglob("*.json"):
        path.write_text(path.read_text().replace(f'"seconds_setting": {TRAIN + LOAD}', f'"seconds_setting": {LOAD}'))
    alone = estimate(str(tmp_path / "cached"), target="tiny", source="tiny")
    both = estimate(str(tmp_path / "cached"), target="tiny", source="tiny", trainings_from=str(tmp_path / "trained"))
    assert alone["training_seconds"] == 0.0
    assert both["training_seconds"] == pytest.approx(TRAIN * sum(both["trainings"].values()))


def test_a_missing_folder_is_one_line_and_exit_2(tmp_path, capsys):
    assert main([str(tmp_path / "nope")]) == 2
    assert main([str(tmp_path), "--trainings-from", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("no such folder" in e for e in err)
