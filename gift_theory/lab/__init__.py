"""The measurement loop: compare a model with measurements, see where it fails, find the
missing physical effect, add it, fit it, watch the error fall (issue 5).

Public API (a notebook can do everything the ``gift simulate/compare/diagnose/fit``
commands do)::

    meas = load_measurement("chip.npz")                 # CONTRACTS §3, validated
    res = diagnose(key, meas)                           # baseline, p-value, ranking of effects
    fit = fit_effects(key, meas, ["shot"])              # before/after, fitted parameters
    cmp = compare(key, Model(physics), meas)            # discrepancy, floor, p-value
"""

from ._compare import Comparison as Comparison
from ._compare import Model as Model
from ._compare import compare as compare
from ._compare import cell_statistic as cell_statistic
from ._compare import energy_cells as energy_cells
from ._compare import model_shots as model_shots
from ._compare import Reference as Reference
from ._compare import noise_floor as noise_floor
from ._compare import reference as reference
from ._compare import one_step_check as one_step_check
from ._measurement import Measurement as Measurement
from ._measurement import load_csv as load_csv
from ._measurement import load_measurement as load_measurement
from ._measurement import save_csv as save_csv
from ._measurement import save_measurement as save_measurement
from ._measurement import simulate_measurement as simulate_measurement
from ._measurement import validate_arrays as validate_arrays
from ._diagnose import Candidate as Candidate
from ._diagnose import Diagnosis as Diagnosis
from ._diagnose import FitResult as FitResult
from ._diagnose import diagnose as diagnose
from ._diagnose import fit_effects as fit_effects
from ._diagnose import penalised_score as penalised_score
from ._fit import CANDIDATES as CANDIDATES
from ._fit import fit_model as fit_model
from ._fit import lattice_step as lattice_step
from ._fit import split_inputs as split_inputs
from ._where import signatures as signatures
from ._where import where_it_fails as where_it_fails
