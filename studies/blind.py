"""Blind identification studies: measurement files from an independent simulator, scored from labels.

    python -m studies.blind write DIR [--files-per-effect 3] [--seed 0] [--no-taps]            built-in catalogue
    python -m studies.blind write DIR --physics open [--files-per-physics 3] [--nulls N]
                                      [--seed 0] [--no-taps] [--setting random|reference]   physics outside it
    python -m studies.blind write DIR --physics new [--no-taps]        issue 24's second set (+ a null), reference setting
    python -m studies.blind write DIR --physics mesh [--strength default|small|large] [--no-taps]   the MZI-mesh chip
    python -m studies.blind write DIR --physics time [--files-per-physics 3] [--nulls N] [--seed 0] [--no-taps]
                                      issue 48's set: intensity wander, drifting weights, memory, shapes
    python -m studies.blind score DIR [--limit N] [--match TEXT] [--runner inprocess|subprocess] [--keep JSONDIR]
    python -m studies.blind rescore DIR --keep JSONDIR                 score kept diagnose JSONs again
    python -m studies.blind table A.jsonl [B.jsonl ...]                markdown tables of scored rows

``write`` draws, per file, a random architecture (2-4 layers, widths 3-28, tanh), random
weights, inputs, noise level and effect strength, and simulates the chip with
:mod:`studies.contract_sim`, a plain-numpy transcription of reference §2 written from the
contract's text, not from gift's forward pass, so the study sees what a user's own
simulator (or the independent judge's) would produce.

Built-in study: each file holds the reference §3 keys plus ``hidden`` (the effects) and
``hidden_params``; gift never reads them (the byte content of these files is unchanged since
the study lived in gift_theory/lab). Open study (``--physics open``): the files hold the
reference §3 keys only, and the labels -- physics, reference §6 mechanism class, the layers
where a one-step check must fail, ``expressible_by``, parameters -- go to ``DIR/labels.json``;
``--setting reference`` pins the network to 8-16-8-4, 160 inputs x 48 shots, s = 0.1.

Mesh study (``--physics mesh``): :mod:`studies.mesh_sim`, an MZI-mesh chip (SVD, Clements
meshes, attenuators, homodyne readout) with its imperfections, on a 16-32-16-8 network,
240 inputs x 64 shots, s = 0.05; labels (class, accepted classes, layers) in labels.json.

``score`` runs ``gift diagnose FILE --json --seed i --quiet`` on the i-th file (sorted) --
through the ``gift`` console entry point in this process (default), or one ``gift`` process
per file (``--runner subprocess``) -- and prints one JSON line per file and a summary. It
reads only the reference §4/§6 JSON: detection (missing_effect_detected), identification
(built-in study: the hidden effect ranked first; for two effects both among the top three
names, or the top entry is the pair), false alarms on null files, the p-value after fitting
the winner, and (:func:`score_row`) ``explained`` correct, wrong explanations, failing
layers exact, mechanism class first; a field the JSON lacks is scored as missing (null).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import time
import zlib

import numpy as np

from .contract_sim import CLASS_OF, NEW_PHYSICS, OPEN_PHYSICS, loguniform, simulate_contract
from .mesh_sim import DEFAULT_STRENGTH, MESH_PHYSICS, MESH_SETTING, simulate_mesh, uniform_loss_gain

#: effects of the study and the range each parameter is drawn from (log-uniform for scales)
EFFECTS = ("none", "laplace", "uniform", "multiplicative", "common_mode", "drift", "crosstalk", "weight_error",
           "shot", "saturation", "quantization", "shot+crosstalk", "multiplicative+common_mode")


#: the reference setting of the open study's strengths (issue 14): 8-16-8-4, 160 inputs x 48 shots, s = 0.1
REFERENCE = {"widths": (8, 16, 8, 4), "n": 160, "r": 48, "s": 0.1}


def _draw_setting(rng, taps: bool, fixed=None):
    """A random network, inputs and noise level; ``fixed`` (like ``REFERENCE``) pins widths, n, r and s."""
    if fixed is None:
        L = int(rng.integers(2, 5))
        widths = [int(rng.integers(3, 21))] + [int(rng.integers(6, 29)) for _ in range(L - 1)] + [int(rng.integers(2, 11))]
    else:
        widths = list(fixed["widths"])
        L = len(widths) - 1
    gain = rng.uniform(0.8, 2.0)
    Ws = [rng.normal(0.0, gain / np.sqrt(widths[l]), (widths[l + 1], widths[l])) for l in range(L)]
    bs = [rng.normal(0.0, rng.uniform(0.0, 0.5), widths[l + 1]) for l in range(L)]
    n = int(rng.choice([120, 240])) if fixed is None else int(fixed["n"])
    r = int(rng.choice([32, 64])) if fixed is None else int(fixed["r"])
    kind = rng.integers(3)
    x = (rng.uniform(0, 1, (n, widths[0])) if kind == 0 else rng.uniform(-1, 1, (n, widths[0])) if kind == 1
         else rng.normal(0, 1, (n, widths[0])))
    s = loguniform(rng, 0.03, 0.15) if fixed is None else float(fixed["s"])
    return widths, Ws, bs, x, n, r, s


def _effect_params(rng, name, typical):
    """A visible but not overwhelming strength of ``name``; ``typical`` = rms of layer outputs."""
    if name == "multiplicative":
        return {"m": loguniform(rng, 0.1, 0.3)}
    if name == "common_mode":
        return {"c": loguniform(rng, 0.05, 0.2)}
    if name == "drift":
        return {"r": float(rng.choice([-1, 1]) * rng.uniform(0.15, 0.5))}
    if name == "crosstalk":
        return {"k": float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.3))}
    if name == "weight_error":
        return {"e": loguniform(rng, 0.05, 0.2)}
    if name == "shot":
        return {"q": loguniform(rng, 0.01, 0.05)}
    if name == "saturation":
        return {"v_max": float(typical * rng.uniform(0.8, 2.0))}
    if name == "quantization":
        return {"bits": float(rng.integers(4, 8)), "v_range": float(typical * rng.uniform(2.5, 5.0))}
    return {}


def write(folder, files_per_effect: int, seed: int, taps: bool, effects=EFFECTS):
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    written = []
    for name in effects:
        for i in range(files_per_effect):
            widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps)
            # the rms of the noiseless layer outputs sets saturation's and quantization's scale
            y0, tp0, _ = simulate_contract(np.random.default_rng(0), widths, Ws, bs, x, 2, 0.0, {})
            typical = float(np.sqrt(np.mean(np.concatenate([np.ravel(v) for v in tp0 + [y0]]) ** 2)))
            hidden = {} if name == "none" else {e: _effect_params(rng, e, typical) for e in name.split("+")}
            y, tp, t = simulate_contract(rng, widths, Ws, bs, x, r, s, hidden)
            arrays = {"x": x, "y": y, "t": t, "activation": np.array("tanh"),
                      "hidden": np.array(name), "hidden_params": np.array(json.dumps({"s": s, **hidden}))}
            for l, (W, b) in enumerate(zip(Ws, bs), start=1):
                arrays[f"W{l}"], arrays[f"b{l}"] = W, b
            if taps:
                for l, a in enumerate(tp, start=1):
                    arrays[f"a{l}"] = a
            path = os.path.join(folder, f"{name}_{i}.npz")
            np.savez(path, **arrays)
            written.append(path)
            sys.stderr.write(f"wrote {path}: arch {'-'.join(map(str, widths))}, n={n}, r={r}, s={s:.3g}, "
                             f"{json.dumps(hidden)}\n")
    return written


def _jsonable(v, digits=6):
    """A label value for JSON: arrays (and lists of them) as rounded lists."""
    if isinstance(v, np.ndarray):
        return np.round(v, digits).tolist()
    if isinstance(v, (list, tuple)):
        return [_jsonable(x, digits) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x, digits) for k, x in v.items()}
    if isinstance(v, np.generic):
        return v.item()
    return v


def _save_measurement(folder, fname, x, y, t, Ws, bs, tp, taps):
    """The reference §3 keys only (no label ever goes into a file gift reads)."""
    arrays = {"x": x, "y": y, "t": t, "activation": np.array("tanh")}
    for l, (W, b) in enumerate(zip(Ws, bs), start=1):
        arrays[f"W{l}"], arrays[f"b{l}"] = W, b
    if taps:
        for l, a in enumerate(tp, start=1):
            arrays[f"a{l}"] = a
    np.savez(os.path.join(folder, fname), **arrays)


def _open_settings(physics, files_per_physics: int, nulls: int):
    return [(name, i) for name in physics for i in range(files_per_physics)] + [("none", i) for i in range(nulls)]


def write_open(folder, files_per_physics: int, seed: int, taps: bool, physics=tuple(OPEN_PHYSICS), nulls=None,
               setting="random"):
    """Files for physics outside the catalogue (and null files); labels go to ``folder/labels.json``.

    The ``.npz`` files hold only reference §3 keys, so what gift reads carries no label. Each
    file's draws come from its own stream, named by the seed, the physics and the file's index.
    """
    for name in physics:
        if name not in OPEN_PHYSICS:
            raise ValueError(f"--only: unknown physics {name!r}; known: {', '.join(OPEN_PHYSICS)}")
    os.makedirs(folder, exist_ok=True)
    fixed = REFERENCE if setting == "reference" else None
    labels = {}
    for name, i in _open_settings(physics, files_per_physics, files_per_physics if nulls is None else nulls):
        rng = np.random.default_rng([seed, zlib.crc32(name.encode()), i])
        widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps, fixed)
        L = len(Ws)
        spec = OPEN_PHYSICS.get(name)
        params = spec.draw(rng, widths, n, r) if spec else {}
        y, tp, t = simulate_contract(rng, widths, Ws, bs, x, r, s, {name: params} if spec else {})
        fname = f"{name}_{i}.npz"
        _save_measurement(folder, fname, x, y, t, Ws, bs, tp, taps)
        shown = _jsonable({k: v for k, v in params.items() if k != "C"})  # the dense coupling is re-made from the seed
        labels[fname] = {"physics": name, "mechanism": spec.mechanism if spec else None,
                         "classes": spec.classes() if spec else [],
                         "layers": spec.layers(L, params) if spec else [],
                         "expressible_by": list(spec.expressible_by) if spec else [],
                         "contained_in": list(spec.contained_in) if spec else [],
                         "definition": spec.definition if spec else "no effect beyond awgn",
                         "params": {"s": s, **shown}, "arch": widths, "n": n, "r": r, "taps": taps,
                         "seed": seed, "setting": setting}
        sys.stderr.write(f"wrote {fname}: arch {'-'.join(map(str, widths))}, n={n}, r={r}, s={s:.3g}, {name} "
                         f"{json.dumps({k: v for k, v in shown.items() if not isinstance(v, list)})}\n")
    with open(os.path.join(folder, "labels.json"), "w") as f:
        json.dump(labels, f, indent=1)
    return sorted(labels)


def write_mesh(folder, files_per_physics: int, seed: int, taps: bool, physics=tuple(MESH_PHYSICS), strength=None,
               setting=MESH_SETTING):
    """Files from the MZI-mesh chip (:mod:`studies.mesh_sim`) on its 16-32-16-8 setting; labels to ``labels.json``.

    ``strength``: "small" | "large" for every physics, or None for ``DEFAULT_STRENGTH`` (the
    weight errors small, loss and crosstalk large). Each file's draws come from its own stream
    (seed, physics, index), so the files with and without taps hold the same shots. ``setting``:
    {"widths", "n", "r", "s"} (tests use a small one).
    """
    for name in physics:
        if name not in MESH_PHYSICS:
            raise ValueError(f"--only: unknown mesh physics {name!r}; known: {', '.join(MESH_PHYSICS)}")
    os.makedirs(folder, exist_ok=True)
    labels = {}
    for name in physics:
        spec = MESH_PHYSICS[name]
        level = strength or DEFAULT_STRENGTH[name]
        for i in range(files_per_physics):
            rng = np.random.default_rng([seed, zlib.crc32(name.encode()), i])
            widths, Ws, bs, x, n, r, s = _draw_setting(rng, taps, setting)
            L = len(Ws)
            imp = spec.imperfections(L, level)
            y, tp, t, Weffs = simulate_mesh(rng, Ws, bs, x, r, s, imp)
            fname = f"{name}_{i}.npz"
            _save_measurement(folder, fname, x, y, t, Ws, bs, tp, taps)
            rel = [float(np.linalg.norm(We - W) / np.linalg.norm(W)) for We, W in zip(Weffs, Ws)]
            params = {"s": s, "strength": level,
                      **{k: v for k, v in vars(imp).items() if k != "layers" and v},
                      "imperfection_layers": {k: list(v) for k, v in imp.layers.items()},
                      "relative_weight_error": rel}
            if imp.loss_db:
                params["g"] = [uniform_loss_gain(W.shape, imp.on("loss_db", l)) for l, W in enumerate(Ws, 1)]
            labels[fname] = {"physics": name, "mechanism": spec.mechanism, "classes": list(spec.accepted),
                             "layers": spec.layers(L), "expressible_by": list(spec.expressible_by),
                             "contained_in": list(spec.contained_in), "definition": spec.definition,
                             "params": params, "arch": widths, "n": n, "r": r, "taps": taps, "seed": seed,
                             "setting": "mesh"}
            sys.stderr.write(f"wrote {fname}: arch {'-'.join(map(str, widths))}, n={n}, r={r}, s={s:.3g}, {name} "
                             f"{level}, ||W_eff - W|| / ||W|| = {np.round(rel, 3).tolist()}\n")
    with open(os.path.join(folder, "labels.json"), "w") as f:
        json.dump(labels, f, indent=1)
    return sorted(labels)


# ---------------------------------------------------------------------------------- scoring

def builtin_label(path):
    """The label of a built-in-catalogue file, read from the file's ``hidden`` keys (never given to gift)."""
    with np.load(path) as z:
        hidden = str(z["hidden"])
        truth = json.loads(str(z["hidden_params"]))
        L = sum(1 for k in z.files if k.startswith("W"))
    effects = [] if hidden == "none" else hidden.split("+")
    return {"physics": hidden, "truth": truth,
            "mechanism": "+".join(CLASS_OF[e] for e in effects) or None,
            "classes": sorted({CLASS_OF[e] for e in effects}),
            "layers": list(range(1, L + 1)) if effects else [],  # every built-in effect acts on every layer
            "expressible_by": ["+".join(sorted(effects))] if effects else []}


def _shape(path):
    with np.load(path) as z:
        Ls = sorted(int(k[1:]) for k in z.files if k[0] == "W" and k[1:].isdigit())
        widths = [int(z["W1"].shape[1])] + [int(z[f"W{l}"].shape[0]) for l in Ls]
        return {"arch": widths, "n": int(z["y"].shape[0]), "r": int(z["y"].shape[1]), "taps": "a1" in z.files}


def run_diagnose(path, seed: int, runner: str = "inprocess", extra=()):
    """``gift diagnose PATH --json --seed SEED --quiet``; returns (JSON object or None, error line or None).

    ``inprocess``: the ``gift`` console entry point called in this process (the command's own
    code path; JAX's compilations are reused across files). ``subprocess``: the ``gift``
    program on PATH, one fresh process per file, exactly as a user types it.
    """
    argv = ["diagnose", path, "--json", "--seed", str(seed), "--quiet", *extra]
    if runner == "subprocess":
        exe = shutil.which("gift")
        if exe is None:
            return None, "no gift program on PATH"
        proc = subprocess.run([exe] + argv, capture_output=True, text=True)
        rc, stdout, err = proc.returncode, proc.stdout, proc.stderr.strip().splitlines()[-1:] or [""]
        err = err[0]
    else:
        from importlib.metadata import entry_points

        (entry,) = [e for e in entry_points(group="console_scripts") if e.name == "gift"]
        buf, ebuf = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(ebuf):
            rc = entry.load()(argv)
        # every file has its own shapes: drop their compiled programs (tens of thousands of
        # memory maps pile up over a study and XLA then fails to allocate)
        import jax

        jax.clear_caches()
        stdout, err = buf.getvalue(), (ebuf.getvalue().strip().splitlines() or [""])[-1]
    if rc != 0:
        return None, f"gift diagnose exit {rc}: {err}"
    try:
        return json.loads(stdout.strip().splitlines()[-1]), None
    except (ValueError, IndexError) as exc:
        return None, f"gift diagnose printed no JSON object ({exc})"


def _entry_name(entry) -> str:
    return "+".join(sorted(list(entry.get("with", [])) + [entry["effect"]]))


def score_row(out, label, taps: bool) -> dict:
    """Score one ``gift diagnose --json`` object against its label (a pure function of the two).

    Columns (None where the JSON lacks the field, or where the question does not apply):

    detected            missing_effect_detected
    explained           the JSON's ``explained``
    explained_correct   ``explained`` equals its right value: true iff the label's
                        ``expressible_by`` is non-empty and the top-ranked entry (its effects,
                        sorted, joined by "+") is in it; on a null file: explained and nothing
                        detected (a false alarm is wrong whatever ``explained`` says)
    wrong_explanation   ``explained`` true where its right value is false (on a null file: true
                        and a missing effect claimed); ``wrong_by_baseline``: of these, the
                        baseline passed (nothing detected, so "explained" by awgn alone)
    expressible_top     the top-ranked entry is in ``expressible_by`` (None if that is empty)
    failing_layers_exact  with taps: the set ``failing_layers`` equals the label's layers
    one_step_layers_exact with taps: the layers whose ``where`` p-value is below 0.01 / L
                        (Bonferroni) equal the label's layers (the scorer's reading, for a
                        diagnose that has ``where`` but no ``failing_layers``)
    mechanism_first     ``mechanisms[0].mechanism`` is one of the label's accepted classes
                        (``classes``: for a pair of built-in effects their classes; for the
                        mesh's phase jitter input_dependent_noise or correlated_noise; otherwise
                        the label's ``mechanism``); None on a null file
    container_explained a wrong explanation whose top entry is in the label's ``contained_in``
                        (a model that contains the physics without being it: over-flexible)
    status_first        ranking[0]'s ``status`` (reference §6, 2026-11-25; None if absent)
    rejected_first      a rejected effect first: ranking[0] is rejected while another entry
                        passes or is refused. With ``status`` on the entries: ranking[0] "fails"
                        and another is "passes" or "refused"; without it: ranking[0]'s
                        p_value_after < 0.01 and another entry's >= 0.01. None without a ranking
    """
    ranking = out.get("ranking") or []
    top = _entry_name(ranking[0]) if ranking else None
    detected = bool(out.get("missing_effect_detected"))
    null = label["physics"] == "none"
    expressible = list(label.get("expressible_by", []))
    explained = out.get("explained")
    right = bool(expressible) and top in expressible
    row = {"detected": detected, "baseline_p": (out.get("baseline") or {}).get("p_value"),
           "ranking": [r["effect"] for r in ranking[:4]],
           "first_entry": sorted(list(ranking[0].get("with", [])) + [ranking[0]["effect"]]) if ranking else [],
           "p_after": ranking[0].get("p_value_after") if ranking else None,
           "params_first": ranking[0].get("params") if ranking else None,
           "explained": explained,
           "explained_correct": (None if explained is None
                                 else bool(explained) and not detected if null else bool(explained) == right),
           "expressible_top": (top in expressible) if expressible else None}
    wrong = None if explained is None else bool(explained) and (detected if null else not right)
    row["wrong_explanation"] = wrong
    row["wrong_by_baseline"] = None if wrong is None else bool(wrong and not detected)
    failing = out.get("failing_layers")
    row["failing_layers"] = failing
    row["failing_layers_exact"] = (None if not taps or failing is None
                                   else sorted(set(failing)) == sorted(set(label["layers"])))
    mechs = out.get("mechanisms")
    row["mechanisms"] = None if mechs is None else [m.get("mechanism") for m in mechs[:3]]
    classes = label.get("classes") or ([label["mechanism"]] if label.get("mechanism") else [])
    row["mechanism_first"] = (None if mechs is None or null
                              else bool(mechs) and mechs[0].get("mechanism") in classes)
    row["container_explained"] = None if wrong is None else bool(wrong and top in label.get("contained_in", []))
    row["status_first"] = ranking[0].get("status") if ranking else None
    row["explained_by"] = out.get("explained_by")  # reference §8 (several: the data cannot choose)
    row["rejected_first"] = rejected_first(ranking)
    steps = {int(w["layer"]): w.get("p_value") for w in out.get("where") or [] if "layer" in w}
    row["one_step_p"] = steps or None
    # the scorer's own reading of the per-layer one-step p-values: fail at 0.01, Bonferroni over the layers
    row["one_step_layers_exact"] = (None if not taps or not steps or any(p is None for p in steps.values())
                                    else sorted(l for l, p in steps.items() if p < 0.01 / len(steps))
                                    == sorted(set(label["layers"])))
    return row


def rejected_first(ranking):
    """True when ranking[0] is an effect the data reject while another entry passes or is refused
    (``status`` where the entries carry it, else p_value_after against 0.01); None without entries."""
    if not ranking:
        return None
    if all("status" in e for e in ranking):
        return ranking[0]["status"] == "fails" and any(e["status"] in ("passes", "refused") for e in ranking[1:])

    def rejected(e):
        p = e.get("p_value_after")
        return p is not None and p < 0.01

    return rejected(ranking[0]) and any(e.get("p_value_after") is not None and not rejected(e) for e in ranking[1:])


def _identified(row, label) -> bool:
    """The built-in study's rule: the hidden effect ranked first; for two, both among the top three
    names or the top entry exactly the pair."""
    want = [] if label["physics"] == "none" else label["physics"].split("+")
    top = row["ranking"][:1] if len(want) < 2 else row["ranking"][:3]
    return bool(want) and (all(h in top for h in want) or (len(want) > 1 and row["first_entry"] == sorted(want)))


_COUNTED = ("detected", "explained_correct", "expressible_top", "wrong_explanation", "wrong_by_baseline",
            "container_explained", "failing_layers_exact", "one_step_layers_exact", "mechanism_first",
            "rejected_first")


def summarize(rows, builtin: bool) -> dict:
    """Per-physics counts (a count of None -- the JSON lacked the field -- is reported as None)."""
    def count(rs, key):
        vals = [r.get(key) for r in rs]
        return None if all(v is None for v in vals) else int(sum(bool(v) for v in vals if v is not None))

    ok = [r for r in rows if not r.get("error")]
    per = {}
    for name in sorted({r["physics"] for r in rows}):
        rs = [r for r in ok if r["physics"] == name]
        per[name] = {"files": len(rs), "errors": sum(1 for r in rows if r["physics"] == name and r.get("error")),
                     **{k: count(rs, k) for k in _COUNTED},
                     "p_after_ok": int(sum((r["p_after"] or 0.0) >= 0.01 for r in rs))}
        if builtin:
            per[name]["identified"] = int(sum(r["identified"] for r in rs))
    eff = [r for r in ok if r["physics"] != "none"]
    null = [r for r in ok if r["physics"] == "none"]
    summary = {"summary": True, "files": len(rows), "errors": len(rows) - len(ok),
               ("per_effect" if builtin else "per_physics"): per,
               "detection_rate": float(np.mean([r["detected"] for r in eff])) if eff else None,
               "false_alarm_rate": float(np.mean([r["detected"] for r in null])) if null else None,
               "wrong_explanations": count(ok, "wrong_explanation"),
               "wrong_explanations_by_baseline": count(ok, "wrong_by_baseline"),
               "mechanism_first": count(eff, "mechanism_first"),
               "failing_layers_exact": count(ok, "failing_layers_exact"),
               "rejected_first": count(ok, "rejected_first")}
    if builtin:
        summary["identification_rate"] = float(np.mean([r["identified"] for r in eff])) if eff else None
    return summary


def _row(f, label, shape, res, err, builtin: bool) -> dict:
    row = {"file": f, "physics": label["physics"], "mechanism_label": label["mechanism"],
           "classes_label": label.get("classes"), "layers_label": label["layers"],
           "expressible_by": label["expressible_by"], **shape}
    if builtin:
        row.update(hidden=label["physics"], truth=label["truth"])
    else:
        row.update(params=label["params"], contained_in=label.get("contained_in", []))
    if err:
        row["error"] = err
    else:
        row.update(score_row(res, label, shape["taps"]))
        if builtin:
            row["identified"] = _identified(row, label)
    return row


def rescore(folder, kept, out=sys.stdout):
    """Score again the ``gift diagnose --json`` objects kept by ``score --keep`` (no gift run):
    the scorer's columns as they are now, on the answers of the code that made them."""
    with open(os.path.join(folder, "labels.json")) as f:
        labels = json.load(f)
    rows = []
    for f in sorted(labels):
        path = os.path.join(kept, f[:-4] + ".json")
        if not os.path.exists(path):
            row = _row(f, labels[f], _shape(os.path.join(folder, f)), None, f"no kept JSON {path}", builtin=False)
        else:
            with open(path) as fh:
                row = _row(f, labels[f], _shape(os.path.join(folder, f)), json.load(fh), None, builtin=False)
        rows.append(row)
        out.write(json.dumps(row) + "\n")
    summary = summarize(rows, builtin=False)
    out.write(json.dumps(summary) + "\n")
    return summary


def score(folder, limit=None, out=sys.stdout, runner="inprocess", match=None, keep=None):
    """Run ``gift diagnose`` on every file of ``folder`` and score it from the labels.

    Labels come from ``folder/labels.json`` (open study) or, for the built-in study, from each
    file's ``hidden`` keys, which gift never reads. File i (in sorted order) is diagnosed with
    ``--seed i``, so the built-in study's numbers are those of ``diagnose(PRNGKey(i), ...)``;
    ``match`` scores only the files whose name contains it, with the same seeds as a full run;
    ``keep``: a folder to write each file's whole ``gift diagnose --json`` object to
    (``FILE.json``), for a later look at what the scorer does not read.
    """
    if not os.path.isdir(folder):
        raise ValueError(f"{folder}: no such folder")
    labels_path = os.path.join(folder, "labels.json")
    labels = None
    if os.path.exists(labels_path):
        with open(labels_path) as f:
            labels = json.load(f)
    files = sorted(f for f in os.listdir(folder) if f.endswith(".npz"))[:limit]
    if not files:
        raise ValueError(f"{folder}: no .npz files")
    chosen = [(i, f) for i, f in enumerate(files) if match is None or match in f]
    rows = []
    for k, (i, f) in enumerate(chosen):
        path = os.path.join(folder, f)
        if labels is not None and f not in labels:
            raise ValueError(f"{labels_path}: no label for {f}")
        label = labels[f] if labels is not None else builtin_label(path)
        shape = _shape(path)
        t0 = time.time()
        res, err = run_diagnose(path, i, runner)
        if keep and res is not None:
            os.makedirs(keep, exist_ok=True)
            with open(os.path.join(keep, f[:-4] + ".json"), "w") as fh:
                json.dump(res, fh)
        row = _row(f, label, shape, res, err, builtin=labels is None)
        row["seconds"] = time.time() - t0
        rows.append(row)
        out.write(json.dumps(row) + "\n")
        out.flush()
        sys.stderr.write(f"[{k + 1}/{len(chosen)}] {f}: " + (err if err else
                         f"detected {row['detected']} (p {row['baseline_p']:.2g}) first {row['ranking'][0]} "
                         f"p_after {row['p_after'] if row['p_after'] is None else round(row['p_after'], 3)} "
                         f"explained {row['explained']} failing {row['failing_layers']} "
                         f"mechanism {(row['mechanisms'] or [None])[0]}") + f" ({row['seconds']:.0f} s)\n")
    summary = summarize(rows, builtin=labels is None)
    out.write(json.dumps(summary) + "\n")
    return summary


def _mark(v):
    return "-" if v is None else "yes" if v else "no"


def table(paths, out=None):
    """Markdown tables from score/rescore JSON lines: one per file, then one line per file set.

    paths : JSONL files (each a study set; the summary line is recomputed from the rows).
    Columns: detected (baseline p), explained, wrong explanation, ranking[0] and its
    p_value_after (and status), first mechanism and whether it is an accepted class, failing
    layers and whether exact, a rejected effect first.
    """
    out = sys.stdout if out is None else out
    sets = []
    for path in paths:
        with open(path) as f:
            rows = [json.loads(line) for line in f if line.strip()]
        rows = [r for r in rows if not r.get("summary")]
        sets.append((os.path.basename(path), rows))
        out.write(f"\n{os.path.basename(path)}\n\n")
        out.write("| file | label (accepted classes; layers) | detected (p) | explained | wrong | ranking[0] (p after, status) "
                  "| first mechanism | right class | failing layers | exact | rejected first |\n")
        out.write("|---|---|---|---|---|---|---|---|---|---|---|\n")
        for r in rows:
            if r.get("error"):
                out.write(f"| {r['file']} | {r['physics']} | error: {r['error']} |||||||||\n")
                continue
            classes = r.get("classes_label") or ([r["mechanism_label"]] if r.get("mechanism_label") else [])
            p_after = r.get("p_after")
            out.write(f"| {r['file']} | {'/'.join(classes) or 'none'}; {r['layers_label']} "
                      f"| {_mark(r['detected'])} ({r['baseline_p']:.2g}) | {_mark(r.get('explained'))} "
                      f"| {_mark(r.get('wrong_explanation'))} | {'+'.join(r.get('first_entry') or []) or '-'} "
                      f"({'-' if p_after is None else f'{p_after:.2g}'}, {r.get('status_first') or '-'})"
                      f"{' or ' + ' or '.join(r['explained_by'][1:]) if len(r.get('explained_by') or []) > 1 else ''} "
                      f"| {(r.get('mechanisms') or ['-'])[0] if r.get('mechanisms') else '-'} "
                      f"| {_mark(r.get('mechanism_first'))} | {r.get('failing_layers')} "
                      f"| {_mark(r.get('failing_layers_exact'))} | {_mark(r.get('rejected_first'))} |\n")
    out.write("\n| set | files | detected (effects) | false alarms (nulls) | wrong explanations | first class right "
              "| failing layers exact | rejected effect first |\n|---|---|---|---|---|---|---|---|\n")
    for name, rows in sets:
        ok = [r for r in rows if not r.get("error")]
        eff = [r for r in ok if r["physics"] != "none"]
        null = [r for r in ok if r["physics"] == "none"]

        def frac(rs, key):
            vals = [r.get(key) for r in rs if r.get(key) is not None]
            return f"{sum(bool(v) for v in vals)}/{len(vals)}" if vals else "-"

        out.write(f"| {name} | {len(ok)}{f' (+{len(rows) - len(ok)} errors)' if len(rows) > len(ok) else ''} "
                  f"| {frac(eff, 'detected')} | {frac(null, 'detected')} | {frac(ok, 'wrong_explanation')} "
                  f"| {frac(eff, 'mechanism_first')} | {frac(ok, 'failing_layers_exact')} "
                  f"| {frac(ok, 'rejected_first')} |\n")


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.blind", description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=("write", "score", "rescore", "table"))
    p.add_argument("folder", nargs="+", help="the study folder (table: the JSONL files)")
    p.add_argument("--physics", choices=("builtin", "open", "new", "mesh", "time"), default="builtin",
                   help="write: the built-in catalogue's effects, physics outside it (open; new: issue 24's second "
                        "set, one file each and a null on the reference setting), or the MZI-mesh chip "
                        "(labels in labels.json); time: issue 48's physics in acquisition time and activation "
                        "shapes (studies.time_physics)")
    p.add_argument("--strength", choices=("default", "small", "large"), default="default",
                   help="mesh study: every physics small or large (default: weight errors small, loss and "
                        "crosstalk large)")
    p.add_argument("--files-per-effect", "--files-per-physics", dest="files", type=int, default=None,
                   help="files per effect (default 3; --physics new and mesh: 1)")
    p.add_argument("--nulls", type=int, default=None, help="open study: null files (default: --files-per-physics)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--taps", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--effects", default=",".join(EFFECTS), help="built-in study: the effects (pairs with +)")
    p.add_argument("--only", default=",".join(OPEN_PHYSICS), help="open study: the physics")
    p.add_argument("--setting", choices=("random", "reference"), default=None,
                   help="open study: random networks like the built-in study's (default), or 8-16-8-4, 160 x 48, "
                        "s = 0.1 (the default of --physics new)")
    p.add_argument("--limit", type=int, default=None)
    p.add_argument("--match", default=None, help="score: only files whose name contains this (same seeds as a full run)")
    p.add_argument("--keep", default=None, metavar="DIR", help="score: also write each diagnose JSON to DIR")
    p.add_argument("--runner", choices=("inprocess", "subprocess"), default="inprocess",
                   help="score: the gift entry point in this process, or one gift process per file")
    a = p.parse_args(argv)
    if a.what != "table":
        if len(a.folder) != 1:
            p.error(f"{a.what} takes one folder")
        a.folder = a.folder[0]
    try:
        if a.what == "table":
            table(a.folder)
            return 0
        if a.what == "score":
            score(a.folder, a.limit, runner=a.runner, match=a.match, keep=a.keep)
        elif a.what == "rescore":
            if a.keep is None:
                raise ValueError("rescore needs --keep DIR (the kept diagnose JSONs)")
            rescore(a.folder, a.keep)
        elif a.physics == "open":
            write_open(a.folder, a.files or 3, a.seed, a.taps, tuple(a.only.split(",")), a.nulls, a.setting or "random")
        elif a.physics == "new":
            write_open(a.folder, a.files or 1, a.seed, a.taps, NEW_PHYSICS, 1 if a.nulls is None else a.nulls,
                       a.setting or "reference")
        elif a.physics == "time":
            from .time_physics import write_time
            write_time(a.folder, a.files or 3, a.seed, a.taps, nulls=a.nulls)
        elif a.physics == "mesh":
            write_mesh(a.folder, a.files or 1, a.seed, a.taps, strength=None if a.strength == "default" else a.strength)
        else:
            write(a.folder, a.files or 3, a.seed, a.taps, tuple(a.effects.split(",")))
    except (ValueError, OSError) as exc:
        sys.stderr.write(f"python -m studies.blind {a.what}: {exc}\n")
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
