"""Ours: the error ladder of the measurement loop (issue 5): the model-measurement discrepancy
as the missing effects are added and fitted one at a time, against the noise floor.

A simulated chip (a 16-12-4 tanh net with Glorot weights, 96 inputs, 16 shots each) has awgn
s = 0.05 plus the hidden effects shot (q = 0.02) and crosstalk (k = 0.1). The model starts as
awgn only; ``gift_theory.lab.fit_effects`` adds shot, then crosstalk, fitting on half the
inputs and scoring on the other half. Each rung's discrepancy (± its standard error) and
p-value, and the noise floor (the discrepancy a correctly specified model reaches), are saved
to ``error_ladder.nc`` and drawn from there. Run: ``python -m paper_figures.error_ladder``.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

from ._jobs import needs

NAME = "error_ladder"
LABEL = "ours:error_ladder"
SWEEPS = ()
DATA = "error_ladder.nc"
SETTING = {"widths": (16, 12, 4), "n_inputs": 96, "shots": 16, "s": 0.05, "shot": 0.02, "crosstalk": 0.1, "seed": 0}


def _lab():
    try:
        from gift_theory.lab import fit_effects, simulate_measurement
    except ImportError as exc:
        raise needs("gift_theory.lab.fit_effects and simulate_measurement", "the measurement loop, issue 5") from exc
    return fit_effects, simulate_measurement


def compute(scale, data_dir: str) -> None:
    import jax
    import xarray as xr

    import gift_theory as gt

    from ._sweep import save_dataset

    fit_effects, simulate_measurement = _lab()
    st = SETTING
    k_w, k_x, k_meas, k_fit = jax.random.split(jax.random.PRNGKey(st["seed"]), 4)
    arch = gt.Architecture(st["widths"])
    params = gt.init_params(k_w, arch)
    x = jax.random.uniform(k_x, (st["n_inputs"], st["widths"][0]))
    chip = gt.Physics.create(s=st["s"], shot=st["shot"], crosstalk=st["crosstalk"])
    meas = simulate_measurement(k_meas, params, x, chip, shots=st["shots"])
    res = fit_effects(k_fit, meas, ["shot", "crosstalk"])
    labels = [lab for lab, _ in res.ladder]
    comps = [c for _, c in res.ladder]
    ds = xr.Dataset({"discrepancy": ("rung", [float(c.discrepancy) for c in comps]),
                     "se": ("rung", [float(c.se) for c in comps]),
                     "p_value": ("rung", [float(c.p_value) for c in comps])},
                    coords={"rung": labels})
    last = comps[-1]
    ds.attrs.update(noise_floor=float(last.noise_floor), floor_se=float(last.floor_se), chip=chip.describe(),
                    fitted=str(res.after.params_json()), widths=str(st["widths"]), n_inputs=st["n_inputs"],
                    shots=st["shots"])
    save_dataset(ds, os.path.join(data_dir, DATA))


def load(data_dir: str) -> dict:
    from ._sweep import open_dataset

    return {"ladder": open_dataset(os.path.join(data_dir, DATA))}


def draw(data: dict):
    ds = data["ladder"]
    a = ds.attrs
    fig, ax = plt.subplots(figsize=(6.5, 4))
    xs = np.arange(ds.sizes["rung"])
    ax.errorbar(xs, ds["discrepancy"].values, yerr=2 * ds["se"].values, marker="o", capsize=4,
                label="discrepancy on held-out inputs (±2 s.e.)")
    ax.axhspan(a["noise_floor"] - 2 * a["floor_se"], a["noise_floor"] + 2 * a["floor_se"], color="grey", alpha=0.3,
               label="noise floor (±2 s.e.)")
    for i, p in enumerate(ds["p_value"].values):
        ax.annotate(f"p = {p:.2g}", (xs[i], ds["discrepancy"].values[i]), textcoords="offset points",
                    xytext=(8, 8), fontsize=8)
    ax.set_xticks(xs, list(ds["rung"].values))
    ax.set_ylabel("discrepancy (lower is better)")
    ax.set_title(f"error ladder: chip = {a['chip']}\nnet {a['widths']}, {a['n_inputs']} inputs x {a['shots']} shots",
                 fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
