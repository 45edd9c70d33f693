"""linear_case: deep linear networks in closed form (paper Example ex: linear network).

J_s, minimisers, d/ds grad J, d2/ds2 grad J, the printed Theorem-1 bound
(eq. condition finetuning works linear net), the corrected bound and the true region where
GIFT's direction lowers J_st -- numerically (jax) and symbolically (sympy) -- and plots.
"""

from ._closed import MODES as MODES
from ._closed import Bounds as Bounds
from ._closed import LinearTask as LinearTask
from ._closed import J as J
from ._closed import J_with_biases as J_with_biases
from ._closed import balanced_chain as balanced_chain
from ._closed import chain_printed_rhs as chain_printed_rhs
from ._closed import derivatives as derivatives
from ._closed import example_rhs as example_rhs
from ._closed import isotropic_task as isotropic_task
from ._closed import minimise as minimise
from ._closed import noise_term as noise_term
from ._closed import product as product
from ._closed import product_minimiser as product_minimiser
from ._closed import theorem1_bounds as theorem1_bounds
from ._plots import bound_rhs as bound_rhs
from ._plots import plot_bound_regions as plot_bound_regions
from ._plots import plot_example_curves as plot_example_curves
from ._symbolic import all_noise_critical_points as all_noise_critical_points
from ._symbolic import example as symbolic_example
