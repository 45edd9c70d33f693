"""The figures of ``gift compare``, ``gift fit`` and ``gift diagnose`` as sets, each written beside
its numbers: :func:`save_figures` writes PNGs atomically and, beside each, the ``xarray.Dataset``
it draws as netCDF (the ``*_data`` functions); the drawing itself is :mod:`._figures`. A set holds
each figure as a *drawing* (a ``functools.partial`` of its figure function with its numbers), so
that :class:`._drawing.Drawing` can share them with a helper process (``processes=2``), which
starts on the first of a set while this process computes the numbers of the rest."""

from __future__ import annotations

import dataclasses
import os
from functools import partial

import numpy as np

from ._drawing import Drawing, draw_to, is_numbers
from ._figures import (
    comparison_figure,
    comparison_table,
    correlation_figure,
    error_ladder,
    law_figure,
    moments_figure,
    pairs_figure,
    pit_figure,
    ppc_figure,
    time_figure,
    where_figure,
)


def save_figures(figures: dict, folder: str, data: dict | None = None, processes: int = 1,
                 meanwhile=None) -> list[str]:
    """Write ``{file name: figure}`` into ``folder`` (created), each atomically; a figure is a
    matplotlib Figure or a drawing (a callable returning one). Beside each PNG whose name ``data``
    holds, its numbers as netCDF (same stem, ``.nc``: an ``xarray.Dataset`` other tools can
    redraw). ``processes=2`` draws them in this process and one helper process together
    (:class:`._drawing.Drawing`: the same files, sooner on two cores); ``meanwhile``, a callable
    that does not need the figures, is run in this process while the helper starts drawing. The
    PNG paths written, in the order of ``figures``."""
    with Drawing(processes) as drawing:
        paths = _hand_over(drawing, figures, data, folder=folder)
        drawing.finish(meanwhile)
    return paths


def _hand_over(drawing, figures: dict, data: dict | None = None, *, folder: str) -> list[str]:
    """Hand ``drawing`` the drawings of ``figures`` and the writing of their numbers (``data``:
    each an ``xarray.Dataset`` or a callable returning one, written as netCDF beside its PNG) into
    ``folder``, the costliest first; their PNG paths, in the order of ``figures``."""
    jobs = [(f, os.path.join(folder, name)) for name, f in figures.items()]
    jobs += [(ds, os.path.join(folder, os.path.splitext(name)[0] + ".nc")) for name, ds in (data or {}).items()
             if name in figures and ds is not None]
    drawing.add(jobs, [_COST.get(_kind(p), 1.0) for _, p in jobs])
    return [p for _, p in jobs if not is_numbers(p)]


#: the relative cost of drawing each kind of figure (t240's figures drawn warm, in units of the
#: correlation figure's 0.4 s: where.png's 56 rows of cells the largest, a ppc figure's 16 panels
#: next; a kind not listed counts 1) and of writing a figure's numbers (``nc``): the costliest are
#: taken first, so that the two processes end together
_COST = {"where": 3.0, "ppc": 1.7, "moments": 1.3, "correlation": 1.0, "pit": 0.6, "law": 0.6, "time": 0.5,
         "comparison": 0.4, "ladder": 0.3, "nc": 0.1}


def _kind(path: str) -> str:
    return "nc" if is_numbers(path) else os.path.basename(path).split("_")[0].split(".")[0]


def _layer_only(obj, layer: int):
    """A :class:`~._compare.Moments` or :class:`~._compare.PredictiveShots` with every other
    layer's arrays left out (None): what its figure of ``layer`` draws, and all a helper process
    is sent."""
    li = list(obj.layer_ids).index(layer)
    return dataclasses.replace(obj, **{
        f.name: [v if j == li else None for j, v in enumerate(getattr(obj, f.name))]
        for f in dataclasses.fields(obj) if isinstance(getattr(obj, f.name), list)})


# ---- the numbers behind each figure, as xarray Datasets ----------------------------------------

def _xr():
    import xarray as xr

    return xr


def where_data(stats: dict):
    """The where-figure's maps (row, bin) with the bins' edges."""
    xr = _xr()
    v = {name: (("row", "bin"), np.asarray(M, float)) for name, M in stats["maps"].items()}
    if stats.get("edges") is not None:
        v["edges"] = (("edge",), np.asarray(stats["edges"], float))
    return xr.Dataset(v, coords={"row": list(stats["rows"])}, attrs={
        "description": "per cell z (N(0, 1) under the model) summed over the inputs of each bin of the model's "
                       "pre-activation, divided by sqrt(count); gift_theory.lab.where_it_fails"})


def pit_data(stats: dict):
    """The PIT histograms: counts per layer (pit_bin), the cells behind them in the attributes."""
    xr = _xr()
    return xr.Dataset({f"pit_layer{l}": (("pit_bin",), np.asarray(c, float)) for l, c in stats["pit"].items()},
                      attrs={f"pit_cells_layer{l}": int(c) for l, c in stats["pit_cells"].items()})


def correlation_data(stats: dict):
    """The correlation z per layer (neuron, neuron)."""
    xr = _xr()
    return xr.Dataset({f"correlation_z_layer{l}": ((f"neuron_l{l}", f"neuron_l{l}_other"), np.asarray(C, float))
                       for l, C in stats["correlation"].items()})


def law_data(stats: dict):
    """The quantiles of the standardised shots per layer (probability), both kurtoses in the attributes."""
    from ._localise import QQ_PROBS

    xr = _xr()
    v = {}
    for l, q in stats["qq"].items():
        v[f"qq_measured_layer{l}"] = (("probability",), np.asarray(q["measured"], float))
        v[f"qq_model_layer{l}"] = (("probability",), np.asarray(q["model"], float))
    return xr.Dataset(v, coords={"probability": QQ_PROBS},
                      attrs={f"kurtosis_{w}_layer{l}": float(q[f"kurtosis_{w}"]) for l, q in stats["qq"].items()
                             for w in ("measured", "model")})


def moments_data(moments, layer: int):
    """One layer's measured and model means and variances (model, input, neuron)."""
    xr = _xr()
    mlist = [moments] if hasattr(moments, "layer_ids") else list(moments)
    li = list(mlist[0].layer_ids).index(layer)
    return xr.Dataset({"measured_mean": (("input", "neuron"), np.asarray(mlist[0].mean[li], float)),
                       "measured_var": (("input", "neuron"), np.asarray(mlist[0].var[li], float)),
                       "model_mean": (("model", "input", "neuron"), np.stack([m.model_mean[li] for m in mlist])),
                       "model_var": (("model", "input", "neuron"), np.stack([m.model_var[li] for m in mlist]))},
                      coords={"model": [m.label for m in mlist]},
                      attrs={"layer": int(layer), "r": int(mlist[0].r), "K": int(mlist[0].K)})


def ppc_data(pred, layer: int):
    """One layer's measured shots (input, shot, neuron) and each model's (model, input, model_shot,
    neuron): ArviZ's observed and posterior-predictive groups."""
    xr = _xr()
    plist = [pred] if hasattr(pred, "layer_ids") else list(pred)
    li = list(plist[0].layer_ids).index(layer)
    return xr.Dataset({"measured": (("input", "shot", "neuron"), np.asarray(plist[0].measured[li], float)),
                       "model_shots": (("model", "input", "model_shot", "neuron"),
                                 np.stack([np.asarray(p.model[li], float) for p in plist]))},
                      coords={"model": [p.label for p in plist]}, attrs={"layer": int(layer)})


def time_data(data: dict):
    """The time figure's numbers: per layer, the residual's mean, se and count in each bin of
    acquisition time (bin), the bins' centres, and the acquisition order in the attributes."""
    xr = _xr()
    layers = [l for l in data if isinstance(l, int)]
    v = {}
    for l in layers:
        for k in ("mean", "se", "count"):
            v[f"{k}_layer{l}"] = (("bin",), np.asarray(data[l][k], float))
    centres = np.asarray(data[layers[0]]["t"], float) if layers else np.zeros(0)
    return xr.Dataset(v, coords={"t": (("bin",), centres)}, attrs={"order": str(data.get("order", ""))})


def ladder_data(rungs, noise_floor: float, floor_se: float):
    xr = _xr()
    return xr.Dataset({"discrepancy": (("model",), np.array([r[1] for r in rungs], float)),
                       "sd": (("model",), np.array([r[2] for r in rungs], float)),
                       "p_value": (("model",), np.array([r[3] for r in rungs], float))},
                      coords={"model": [r[0] for r in rungs]},
                      attrs={"noise_floor": float(noise_floor), "floor_se": float(floor_se)})


def comparison_data(table: list, noise_floor: float, floor_se: float):
    xr = _xr()
    cols = ("discrepancy", "sd", "delta", "delta_se", "p_value")
    return xr.Dataset({c: (("model",), np.array([t[c] for t in table], float)) for c in cols}
                      | {"status": (("model",), np.array([t["status"] or "" for t in table], dtype=str))},
                      coords={"model": [t["model"] for t in table]},
                      attrs={"noise_floor": float(noise_floor), "floor_se": float(floor_se),
                             "difference_to": table[0]["model"]})


def pairs_data(joint: dict):
    xr = _xr()
    names = list(joint["params"])
    return xr.Dataset({"estimate": (("param",), np.asarray(joint["estimate"], float)),
                       "centre_fit_scale": (("param",), np.asarray(joint["centre"], float)),
                       "cov_fit_scale": (("param", "param_other"), np.asarray(joint["cov"], float)),
                       "fit_scale": (("param",), np.array(joint["scale"], dtype=str))},
                      coords={"param": names, "param_other": names},
                      attrs={"level": float(joint.get("level", 0.95))})


# ---- the figure sets of the commands -----------------------------------------------------------

def where_figures(stats: dict, model: str) -> tuple[dict, dict]:
    """The where-figure and the law of the shots (PIT, correlations, quantiles) of one
    :func:`~gift_theory.lab.where_it_fails` result, ``model`` its model's name in the titles:
    ``(figures, data)``."""
    title = model
    figs = {"where.png": partial(where_figure, stats, title=f"{model}: where it fails")}
    data = {"where.png": partial(where_data, stats)}
    if stats.get("pit"):
        figs["pit.png"] = partial(pit_figure, stats, title=f"{title}: PIT of the measured shots among the model's own")
        data["pit.png"] = partial(pit_data, stats)
        figs["correlation.png"] = partial(correlation_figure, stats, title=f"{title}: correlation between neurons")
        data["correlation.png"] = partial(correlation_data, stats)
        figs["law.png"] = partial(law_figure, stats, title=f"{title}: quantiles of the standardised shots")
        data["law.png"] = partial(law_data, stats)
    return figs, data


def predictive_figures(key, models, meas) -> tuple[dict, dict]:
    """Each measured layer's moments and posterior-predictive overlay under each of ``models``
    ((label, Model), common random numbers), ``(figures, data)``."""
    from .._model import named_subkey
    from ._compare import predictive_shots

    k = named_subkey(key, "figure_moments")  # common random numbers: every model the same draws
    preds = [predictive_shots(k, m, meas, label=lab) for lab, m in models]
    mom = [p.moments() for p in preds]
    figs, data = {}, {}
    for l in meas.layer_ids():
        figs[f"moments_layer{l}.png"] = partial(moments_figure, [_layer_only(m, l) for m in mom], l)
        data[f"moments_layer{l}.png"] = partial(moments_data, [_layer_only(m, l) for m in mom], l)
        figs[f"ppc_layer{l}.png"] = partial(ppc_figure, [_layer_only(p, l) for p in preds], l)
        data[f"ppc_layer{l}.png"] = partial(ppc_data, [_layer_only(p, l) for p in preds], l)
    return figs, data


def diagnosis_figures(diagnosis, folder: str, meas=None, key=None, processes: int = 1,
                      meanwhile=None) -> list[str]:
    """The figures of a :class:`~gift_theory.lab.Diagnosis`, written to ``folder`` (each PNG with
    its numbers as netCDF beside it): the error ladder of the baseline and the three best
    candidates; the model comparison of the baseline and every ranked candidate (differences to
    ranking[0] with their paired standard errors); where the baseline fails and its law of the
    shots (PIT, correlations, quantiles); given the measurement, each measured layer's moments
    and posterior-predictive overlay under the baseline and the top-ranked model on the
    held-out inputs, and with acquisition times each layer's residual against them
    (:func:`time_figure`). ``processes``, ``meanwhile``: as in :func:`save_figures`.
    :class:`DiagnosisFigures` draws the same files while the diagnosis runs."""
    with DiagnosisFigures(folder, meas=meas, key=key, processes=processes) as figures:
        return figures.finish(diagnosis, meanwhile)


class DiagnosisFigures:
    """The files of :func:`diagnosis_figures`, drawn as their numbers are ready: those that need
    only the baseline and the final ranking (the error ladder, the moments and
    posterior-predictive overlays, the residual in time) when :meth:`ranked` is called -- by
    :func:`~gift_theory.lab.diagnose`, while its localisation still runs, so that a helper
    process (``processes=2``) draws them on the core the diagnosis leaves idle -- and the rest
    (the model comparison, where the baseline fails and its law of the shots) in :meth:`finish`.

    The files are written into a hidden folder inside ``folder`` and moved into ``folder`` only
    when every one of them is drawn, so ``folder`` never holds a mix of two runs' figures: leaving
    the context on an error (a diagnosis that fails after its ranking) removes them, and the
    folders this run made. Use::

        with DiagnosisFigures(folder, meas=meas, key=key, processes=2) as figures:
            diagnosis = diagnose(key, meas, ranked=figures.ranked)
            paths = figures.finish(diagnosis)
    """

    #: the files' order in :meth:`finish`'s list (then the layers' moments and ppc, then time)
    ORDER = ("ladder.png", "comparison.png", "where.png", "pit.png", "correlation.png", "law.png")

    def __init__(self, folder: str, meas=None, key=None, processes: int = 1):
        self.folder, self.meas, self.key, self.processes = folder, meas, key, processes
        self.drawing: Drawing | None = None
        self.stage: str | None = None  # the hidden folder the files are drawn into
        self.names: list[str] = []  # the files' names, as handed over
        self.early = False
        self.made: list[str] = []  # the folders this run made

    def __enter__(self):
        import tempfile

        here = os.path.abspath(self.folder)
        while not os.path.isdir(here):  # the folders this run makes, the innermost first
            self.made.append(here)
            here = os.path.dirname(here)
        os.makedirs(self.folder, exist_ok=True)
        self.stage = tempfile.mkdtemp(prefix=".drawing-", dir=self.folder)
        self.drawing = Drawing(self.processes).__enter__()
        return self

    def __exit__(self, kind, value, tb):
        import shutil

        try:
            self.drawing.__exit__(kind, value, tb)
        finally:
            shutil.rmtree(self.stage, ignore_errors=True)  # after finish: empty; after an error: this run's files
            for made in self.made if kind is not None else ():  # folders made for a run that failed
                if os.path.isdir(made) and not os.listdir(made):
                    os.rmdir(made)
        return False

    def _hand_over(self, figs: dict, data: dict) -> None:
        self.names += list(figs)
        _hand_over(self.drawing, figs, data, folder=self.stage)

    def ranked(self, baseline, baseline_comparison, ranking, held_out) -> None:
        """Hand over the figures of the baseline (a Model), its held-out comparison, the final
        ranking and the held-out inputs (indices into the measurement): the error ladder and,
        given the measurement, the moments, posterior-predictive and time figures."""
        c = baseline_comparison
        rungs = [("awgn", c.discrepancy, c.se, c.p_value)] + [
            ("awgn + " + " + ".join(cand.effects), cand.comparison.discrepancy, cand.comparison.se,
             cand.comparison.p_value) for cand in ranking[:3]]
        self._hand_over({"ladder.png": partial(error_ladder, rungs, c.noise_floor, c.floor_se,
                                               title="baseline and best candidates")},
                        {"ladder.png": partial(ladder_data, rungs, c.noise_floor, c.floor_se)})
        self.early = True
        meas = self.meas
        if meas is None:
            return
        import jax

        key = jax.random.PRNGKey(0) if self.key is None else self.key
        models = [("before: " + " + ".join(baseline.effects), baseline)]
        if ranking:
            models.append(("first ranked: " + " + ".join(ranking[0].model.effects), ranking[0].model))
        self._hand_over(*predictive_figures(key, models, meas.subset(held_out)))
        if meas.t is not None:  # the residual against acquisition time, per layer (reference §8)
            from .._model import named_subkey
            from ._time import residual_in_time

            td = residual_in_time(named_subkey(key, "figure_time"), baseline, meas)
            self._hand_over({"time.png": partial(time_figure, td, title="baseline: residual along the signal "
                                                                        "against acquisition time")},
                            {"time.png": partial(time_data, td)})

    def finish(self, diagnosis, meanwhile=None) -> list[str]:
        """Hand over the rest of ``diagnosis``'s figures (all of them if :meth:`ranked` was not
        called), run ``meanwhile`` while they are drawn (as :func:`save_figures`), and move the
        files into the folder; their paths, in the order of :data:`ORDER`, then each layer's
        moments and ppc, then time."""
        if not self.early:
            self.ranked(diagnosis.baseline, diagnosis.baseline_comparison, diagnosis.ranking, diagnosis.held_out)
        c = diagnosis.baseline_comparison
        figs, data = {}, {}
        table = diagnosis_comparison(diagnosis)
        if table:
            figs["comparison.png"] = partial(comparison_figure, table, c.noise_floor, c.floor_se,
                                             title="model comparison on the held-out inputs")
            data["comparison.png"] = partial(comparison_data, table, c.noise_floor, c.floor_se)
        if diagnosis.where is not None:
            f, d = where_figures(diagnosis.where, "the baseline (awgn)")
            figs.update(f)
            data.update(d)
        self._hand_over(figs, data)
        self.drawing.finish(meanwhile)
        for name in sorted(os.listdir(self.stage)):  # every file drawn: into the folder
            os.replace(os.path.join(self.stage, name), os.path.join(self.folder, name))
        last = [n for n in self.names if n not in self.ORDER and n != "time.png"] + ["time.png"]
        return [os.path.join(self.folder, n) for n in list(self.ORDER) + last if n in self.names]


def diagnosis_comparison(diagnosis, limit: int = 10) -> list[dict]:
    """The model comparison rows (:func:`comparison_table`) of a diagnosis: the model its verdict
    names first (ranking[0], or the baseline when the verdict names it), then the baseline and the
    next candidates, each against the first on the held-out inputs."""
    named = [(" + ".join(["awgn"] + list(cand.effects)), cand.comparison, getattr(cand, "status", ""))
             for cand in diagnosis.ranking[:limit] if getattr(cand, "comparison", None) is not None]
    base = ("awgn (baseline)", diagnosis.baseline_comparison, "passes" if getattr(diagnosis, "names_baseline", False)
            else "")
    named = [base] + named if getattr(diagnosis, "names_baseline", False) or not named else named[:1] + [base] + named[1:]
    return comparison_table(named)


def fit_figures(result, folder: str, meas=None, key=None, uncertainty: dict | None = None,
                where: dict | None = None, processes: int = 1, meanwhile=None) -> list[str]:
    """The figures of a :class:`~gift_theory.lab.FitResult`, written to ``folder`` (each PNG with its
    numbers as netCDF beside it): the error ladder and the model comparison of its rungs (each
    against the fitted model, paired standard errors); given ``uncertainty``
    (:func:`~gift_theory.lab._fit.fit_uncertainty` with a ``joint``), the pair plot of the fitted
    parameters; given ``where`` (:func:`~gift_theory.lab.where_it_fails` of the fitted model on the
    held-out inputs), where it fails and its law of the shots; given the measurement, each
    measured layer's moments and posterior-predictive overlay before and after the fit.
    ``processes``, ``meanwhile``: as in :func:`save_figures`."""
    a = result.comparison_after
    rungs = [(lab, c.discrepancy, c.se, c.p_value) for lab, c in result.ladder]
    figs = {"ladder.png": partial(error_ladder, rungs, a.noise_floor, a.floor_se)}
    data = {"ladder.png": partial(ladder_data, rungs, a.noise_floor, a.floor_se)}
    if len(result.ladder) > 1 and all(getattr(c, "channel_values", None) is not None for _, c in result.ladder):
        named = [(lab, c, "") for lab, c in result.ladder][::-1]  # the fitted model first
        table = comparison_table(named)
        figs["comparison.png"] = partial(comparison_figure, table, a.noise_floor, a.floor_se,
                                         title="the ladder compared on the held-out inputs")
        data["comparison.png"] = partial(comparison_data, table, a.noise_floor, a.floor_se)
    if uncertainty and uncertainty.get("joint"):
        figs["pairs.png"] = partial(pairs_figure, uncertainty["joint"])
        data["pairs.png"] = partial(pairs_data, uncertainty["joint"])
    if where is not None:
        f, d = where_figures(where, "the fitted model")
        figs.update(f)
        data.update(d)
    with Drawing(processes) as drawing:
        paths = _hand_over(drawing, figs, data, folder=folder)  # drawn while the model's shots below are drawn
        if meas is not None:
            import jax

            key = jax.random.PRNGKey(0) if key is None else key
            figs, data = predictive_figures(key, [("before: " + " + ".join(result.before.effects), result.before),
                                                  ("after: " + " + ".join(result.after.effects), result.after)], meas)
            paths += _hand_over(drawing, figs, data, folder=folder)
        drawing.finish(meanwhile)
    return paths


def compare_figures(key, model, scored, where: dict, label: str, folder: str, processes: int = 1,
                    meanwhile=None) -> list[str]:
    """The figures of ``gift compare``: where ``model`` fails on the scored inputs and its law of
    the shots, each measured layer's moments and posterior-predictive overlay, written to
    ``folder`` (each PNG with its numbers as netCDF beside it); ``processes``, ``meanwhile``: as
    in :func:`save_figures`."""
    figs, data = where_figures(where, " + ".join(model.effects))
    with Drawing(processes) as drawing:
        paths = _hand_over(drawing, figs, data, folder=folder)  # drawn while the model's shots below are drawn
        figs, data = predictive_figures(key, [(label, model)], scored)
        paths += _hand_over(drawing, figs, data, folder=folder)
        drawing.finish(meanwhile)
    return paths


def heatmaps(stats: dict, path: str, title: str = "where the model fails") -> str:
    """:func:`where_figure` written to ``path`` (atomically); the path."""
    return draw_to(partial(where_figure, stats, title=title), path)
