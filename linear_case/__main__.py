"""``python -m linear_case [FOLDER]``: draw the bound regions and the example curves
(default folder gift-out/linear_case)."""

import os
import sys

import matplotlib

matplotlib.use("agg")  # a script that writes files: no display needed

from gift_theory import save_figure  # noqa: E402

from ._plots import plot_bound_regions, plot_example_curves  # noqa: E402

folder = sys.argv[1] if len(sys.argv) > 1 else os.path.join("gift-out", "linear_case")
print(save_figure(plot_bound_regions(), os.path.join(folder, "bound_regions.png"), bbox_inches=None))
print(save_figure(plot_example_curves(), os.path.join(folder, "example_curves.png"), bbox_inches=None))
