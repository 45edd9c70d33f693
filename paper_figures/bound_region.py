"""Ours: where the printed Theorem-1 bounds admit st, linear example (paper eq. condition
finetuning works linear net, Figure "Values of alpha for which eq. cond_for_improvement holds").

Fine-tuning is guaranteed by the printed statements only for |st - s0| < RHS(s0). This draws
the band s0 - RHS < st < s0 + RHS in the (s0, st) plane for two printed right-hand sides from
``linear_case``: the example's (1 + s0^2/m2) / (2 ||V||) (``linear_case.example_rhs``) and
Theorem 1's 1/||grad B(w0)|| at depth L for the balanced chain
(``linear_case.chain_printed_rhs``); m2 = 1. The values are saved to ``bound_region.nc`` and drawn
from there. linear_case's own ``plot_bound_regions`` adds its corrected bound and the true
region. Run: ``python -m paper_figures.bound_region``.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

from ._linear import linear_api

NAME = "bound_region"
LABEL = "ours:bound_region"
SWEEPS = ()
DATA = "bound_region.nc"


def compute(scale, data_dir: str) -> None:
    import xarray as xr

    from ._sweep import save_dataset

    example_rhs, chain_printed_rhs = linear_api("example_rhs"), linear_api("chain_printed_rhs")
    s0 = np.linspace(1e-3, 2.0, 401)
    depths, vnorms = (1, 2, 3), (0.5, 1.0, 2.0)
    ex = np.stack([np.asarray(example_rhs(s0, 1.0, v), float) for v in vnorms])
    ch = np.stack([np.stack([np.asarray(chain_printed_rhs(s0, L, v, 1.0), float) for L in depths]) for v in vnorms])
    ds = xr.Dataset({"example_rhs": (("V_norm", "s0"), ex), "chain_rhs": (("V_norm", "L", "s0"), ch)},
                    coords={"V_norm": list(vnorms), "L": list(depths), "s0": s0})
    ds.attrs.update(m2=1.0, source="linear_case.example_rhs, linear_case.chain_printed_rhs")
    save_dataset(ds, os.path.join(data_dir, DATA))


def load(data_dir: str) -> dict:
    from ._sweep import open_dataset

    return {"bounds": open_dataset(os.path.join(data_dir, DATA))}


def draw(data: dict):
    ds = data["bounds"]
    s0 = ds["s0"].values
    nV, nL = ds.sizes["V_norm"], ds.sizes["L"]
    fig, axes = plt.subplots(nV, nL, figsize=(3.2 * nL, 3.0 * nV), sharex=True, sharey=True, squeeze=False)
    for i, vn in enumerate(ds["V_norm"].values):
        for j, L in enumerate(ds["L"].values):
            ax = axes[i, j]
            ex = ds["example_rhs"].sel(V_norm=vn).values
            ch = ds["chain_rhs"].sel(V_norm=vn, L=L).values
            ax.fill_between(s0, np.maximum(s0 - ex, 0), s0 + ex, color="red", alpha=0.2,
                            label="printed example bound")
            ax.fill_between(s0, np.maximum(s0 - ch, 0), s0 + ch, color="blue", alpha=0.2,
                            label="printed Thm 1 bound, depth L")
            ax.plot(s0, s0, "k", lw=0.8)
            ax.set_xlim(0, 2)
            ax.set_ylim(0, 2)
            ax.set_title(f"L={L}, ||V||={vn:g}", fontsize=9)
            if i == nV - 1:
                ax.set_xlabel("$s_0$")
            if j == 0:
                ax.set_ylabel("$s_t$")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle("st admitted by the printed bounds |st - s0| < RHS(s0) (linear example, m2 = 1)", fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
