"""paper_figures: regenerate the paper's simulation study (and ours) from resumable sweeps.

One script per figure (``python -m paper_figures.<name>``), each naming the paper figure label
it reproduces; ``python -m paper_figures`` (or ``gift figures``) rebuilds all. Computation and
drawing are separate: sweeps save labelled arrays (xarray -> netCDF) under ``data/<scale>/``,
figures are drawn from those files into ``figures/<scale>/``.

Public API::

    sw = Sweep("name", {"s0": (0.05, 0.1), "seed": (0, 1)}, "module:job", fixed={...})
    ds = run_sweep(sw, "data/", scheduler=None)      # local Dask pool; resumable
    result = build("quick")                          # all sweeps + all figures
"""

from ._build import FIGURES as FIGURES
from ._build import build as build
from ._jobs import NOISE_KINDS as NOISE_KINDS
from ._jobs import estimator_job as estimator_job
from ._jobs import gift_job as gift_job
from ._jobs import true_noise as true_noise
from ._scales import SCALES as SCALES
from ._scales import Scale as Scale
from ._scales import sweeps as sweeps
from ._sweep import Sweep as Sweep
from ._sweep import assemble as assemble
from ._sweep import load_points as load_points
from ._sweep import open_dataset as open_dataset
from ._sweep import point_id as point_id
from ._sweep import run_sweep as run_sweep
from ._sweep import save_dataset as save_dataset
