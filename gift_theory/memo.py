"""The on-disk memo of in-silico work (directions, curvatures, retrained weights) shared between
runs that differ only in the chip: public re-exports of the core's own functions, for the
packages on top of gift (paper_figures' sweeps)."""

from ._memo import clear as clear
from ._memo import counters as counters
from ._memo import digest as digest
from ._memo import folder as folder
from ._memo import use_folder as use_folder
