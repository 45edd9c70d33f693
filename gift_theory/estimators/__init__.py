"""Estimators of derivatives of the objective J_s in the weights and in the physics.

Paper Section "Calculation of (d/ds) grad J". Every estimator averages over the
hierarchical K1 x K2 design and returns an :class:`~gift_theory.Estimate` (mean and
standard error, pytrees shaped like the weights).
"""

from ._directions import D2_DS2_METHODS as D2_DS2_METHODS
from ._directions import D_DS_METHODS as D_DS_METHODS
from ._directions import D_DTHETA_METHODS as D_DTHETA_METHODS
from ._directions import d2_ds2_grad as d2_ds2_grad
from ._directions import d_ds_grad as d_ds_grad
from ._directions import d_dtheta_grad as d_dtheta_grad
from ._directions import grad_objective as grad_objective
from ._directions import hvp as hvp
from ._directions import paper_constant as paper_constant
from ._hierarchical import hierarchical_mean as hierarchical_mean
from ._hierarchical import summarise as summarise
