"""fig:example-fine-tuning -- J_{s0} and J_{st} around their minimisers, from the linear closed forms.

Paper caption: "(Left) Schematic depictions of J_{s0} and J_{st} for some s0 != st. (Right)
The curves around the minimizers of the in situ and ex situ objectives."

Not a schematic here: the one-dimensional linear example J_s(W) = m2 (V - W)^2 + s^2 W^2
evaluated with ``linear_case.J`` (closed form) and its minimisers from
``linear_case.product_minimiser``; V = 1, m2 = 1, s0 = 0.3, st = 0.6. The data (curves and
minimisers) are saved to ``example_fine_tuning.nc`` and drawn from there. Left: both curves;
right: zoom around w0 and wt, showing J_st(wt) < J_st(w0) (Theorem thm:FT-is-needed).
Run: ``python -m paper_figures.example_fine_tuning``.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

from ._linear import linear_api

NAME = "example_fine_tuning"
LABEL = "fig:example-fine-tuning"
SWEEPS = ()
DATA = "example_fine_tuning.nc"
SETTING = {"V": 1.0, "m2": 1.0, "s0": 0.3, "st": 0.6}


def compute(scale, data_dir: str) -> None:
    """Evaluate the closed forms on a grid of W and save them."""
    import jax
    import jax.numpy as jnp
    import xarray as xr

    from ._sweep import save_dataset

    J, isotropic_task, product_minimiser = (linear_api(n) for n in ("J", "isotropic_task", "product_minimiser"))
    V, m2, s0, st = (SETTING[k] for k in ("V", "m2", "s0", "st"))
    task = isotropic_task(V, m2)
    W = np.linspace(-0.2 * V, 1.4 * V, 401)
    with jax.enable_x64(True):
        curve = jax.vmap(lambda w, s: J((jnp.reshape(w, (1, 1)),), s, task, "input"), in_axes=(0, None))
        j0, jt = np.asarray(curve(jnp.asarray(W), s0)), np.asarray(curve(jnp.asarray(W), st))
        w0 = float(np.asarray(product_minimiser(s0, task)).ravel()[0])
        wt = float(np.asarray(product_minimiser(st, task)).ravel()[0])
        at = lambda w, s: float(J((jnp.full((1, 1), w),), s, task, "input"))
        pts = {"J_s0_w0": at(w0, s0), "J_st_w0": at(w0, st), "J_st_wt": at(wt, st)}
    ds = xr.Dataset({"J_s0": ("W", j0), "J_st": ("W", jt)}, coords={"W": W})
    ds.attrs.update(SETTING, w0=w0, wt=wt, **pts, source="linear_case.J, linear_case.product_minimiser")
    save_dataset(ds, os.path.join(data_dir, DATA))


def load(data_dir: str) -> dict:
    from ._sweep import open_dataset

    return {"curves": open_dataset(os.path.join(data_dir, DATA))}


def draw(data: dict):
    ds = data["curves"]
    a = ds.attrs
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for k, ax in enumerate(axes):
        ax.plot(ds["W"], ds["J_s0"], color="red", label=f"$J_{{s_0}}$, $s_0$={a['s0']:g} (ex situ)")
        ax.plot(ds["W"], ds["J_st"], color="green", label=f"$J_{{s_t}}$, $s_t$={a['st']:g} (in situ)")
        ax.plot([a["w0"]], [a["J_s0_w0"]], "o", color="red", label="$w_0$ = argmin $J_{s_0}$")
        ax.plot([a["w0"]], [a["J_st_w0"]], "o", mfc="none", color="green", label="$J_{s_t}(w_0)$")
        ax.plot([a["wt"]], [a["J_st_wt"]], "*", ms=10, color="green", label="$w_t$ = argmin $J_{s_t}$")
        ax.set_xlabel("W")
        ax.set_ylabel("J")
        if k == 1:
            lo, hi = sorted((a["w0"], a["wt"]))
            pad = 0.6 * (hi - lo)
            ax.set_xlim(lo - pad, hi + pad)
            sel = ds.sel(W=slice(lo - pad, hi + pad))
            ys = np.concatenate([sel["J_s0"].values, sel["J_st"].values])
            ax.set_ylim(ys.min() - 0.05 * np.ptp(ys), ys.max() + 0.05 * np.ptp(ys))
            ax.set_title(f"around the minimisers: $J_{{s_t}}(w_0) - J_{{s_t}}(w_t)$ = "
                         f"{a['J_st_w0'] - a['J_st_wt']:.4f} > 0", fontsize=9)
        else:
            ax.set_title(f"$J_s(W) = m_2 (V - W)^2 + s^2 W^2$, V={a['V']:g}, $m_2$={a['m2']:g}", fontsize=9)
            ax.legend(fontsize=7)
    fig.suptitle("fig:example-fine-tuning -- from the closed forms of linear_case (not a schematic)", fontsize=9)
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    from ._build import main

    raise SystemExit(main(only=NAME))
