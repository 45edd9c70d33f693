"""``python -m linear_case [FOLDER]``: draw the bound regions and the example curves
(default folder gift-out/linear_case)."""

import os
import sys

from ._plots import plot_bound_regions, plot_example_curves

folder = sys.argv[1] if len(sys.argv) > 1 else os.path.join("gift-out", "linear_case")
print(plot_bound_regions(os.path.join(folder, "bound_regions.png")))
print(plot_example_curves(os.path.join(folder, "example_curves.png")))
