"""The measurement loop: compare a model with measurements, see where it fails, find the
missing physical effect -- or say plainly that none it knows explains the data -- add it,
fit it, watch the error fall.

The stages, one module each -- which module decides what -- in the order one :func:`diagnose`
runs them::

    _io            measurement files (reference §3; the arrays' rules: gift_theory._measurement)
    _shots         a model of the device and its shots (the core's sampler and forward pass)
    _channels      the channels of a cell and the measurement's noise floor
    _qtest         the discrepancy test
    _compare       one model against one measurement; the one-step check per layer
    _level         the one significance level every test decides at (ALPHA)
    identification each layer's transfer and noise read off the shots; a test per mechanism class
                   (its package docstring maps its modules: statistics, layers and propagation,
                   the map, the map's rows, the noise, time trends, one layer, the network)
    _time          a gain that wanders and a map that drifts over the acquisition (read by
                   identification)
    _memory        the lag test of memory: a shot carrying the shot acquired before it (read by
                   identification)
    _explain_output without taps: candidate mechanisms put into the model, against the output's means
    _fit*          fitting a model: moments, per-device offsets, values read off the data
    _session       one measurement's split, reference, moments and baseline (Session.create);
                   a candidate fitted, scored and checked, purely
    _verdict       the rules: whether a candidate that passes is an explanation, each rule a
                   named function; whether the data are explained; the verdict line
    _ranking       which candidates are fitted, their order, the greedy second step
    _results       Candidate, Diagnosis, FitResult and their JSON
    _localise      where a model fails; each effect's signature
    _mechanisms    the mechanism classes named from the evidence
    _diagnose      the pipeline: the stages above, in order
    _budget        how many threads the lab runs for a file's size (its memory budget), and
                   map_in_threads: the loops of independent keyed work run in them
    _neurons       per-neuron values identified neuron by neuron: an explanation
    _ambiguity     the models the data cannot tell apart (reference §8)
    _design        the next measurement that would tell them apart (reference §8, ``gift design``)
    _figures       drawing each figure from numbers already computed
    _figure_sets   the figures of ``gift compare/fit/diagnose``, each written beside its numbers
    _drawing       drawing them into files, in this process or shared with a helper process
                   (``_draw_helper``)

Public API (a notebook can do everything ``gift simulate/compare/diagnose/fit`` do)::

    meas = load_measurement("chip.npz")                 # reference §3, validated
    res = diagnose(key, meas)                           # baseline, p-value, ranking of effects
    fit = fit_effects(key, meas, ["shot"])              # before/after, fitted parameters
    cmp = compare(key, Model(physics), meas)            # discrepancy, floor, p-value
    ident = identify(meas)                              # per layer: W_eff, noise, class tests
"""

from .._measurement import Measurement as Measurement
from ..chips import simulate_measurement as simulate_measurement
from ._channels import Reference as Reference
from ._channels import cell_statistic as cell_statistic
from ._channels import energy_cells as energy_cells
from ._channels import noise_floor as noise_floor
from ._channels import reference as reference
from ._compare import Comparison as Comparison
from ._compare import compare as compare
from ._compare import one_step_check as one_step_check
from ._compare import power_notes as power_notes
from ._compare import power_of as power_of
from ._compare import predictive_moments as predictive_moments
from ._diagnose import compare_measurement as compare_measurement
from ._diagnose import default_candidates as default_candidates
from ._diagnose import diagnose as diagnose
from ._diagnose import fit_effects as fit_effects
from ._ranking import ranked as ranked
from ._results import STATUSES as STATUSES
from ._results import Candidate as Candidate
from ._results import Diagnosis as Diagnosis
from ._results import FitResult as FitResult
from ._results import penalised_score as penalised_score
from ._session import Session as Session
from ._session import split_inputs as split_inputs
from ._fit import fit_model as fit_model
from ._fit import fit_uncertainty as fit_uncertainty
from ._fit_moments import MomentProblem as MomentProblem
from .identification import Identification as Identification
from .identification import identify as identify
from ._compare import PredictiveShots as PredictiveShots
from ._compare import discrepancy_difference as discrepancy_difference
from ._compare import predictive_shots as predictive_shots
from ._compare import failing_layers as failing_layers
from ._design import Design as Design
from ._design import decide as decide
from ._design import designs as designs
from ._design import hypotheses as hypotheses
from ._design import inputs_arrays as design_inputs
from ._design import next_measurement as next_measurement
from ._design import public as design_json
from ._figure_sets import compare_figures as compare_figures
from ._figure_sets import diagnosis_comparison as diagnosis_comparison
from ._figure_sets import diagnosis_figures as diagnosis_figures
from ._figure_sets import DiagnosisFigures as DiagnosisFigures
from ._figure_sets import fit_figures as fit_figures
from ._figure_sets import save_figures as save_figures
from ._io import NETCDF_EXTENSIONS as NETCDF_EXTENSIONS
from ._io import detect_format as detect_format
from ._offset_kinds import fitted_as_offsets as fitted_as_offsets
from ._figures import comparison_figure as comparison_figure
from ._figures import comparison_table as comparison_table
from ._figures import correlation_figure as correlation_figure
from ._figures import error_ladder as error_ladder
from ._figures import law_figure as law_figure
from ._figures import moments_figure as moments_figure
from ._figures import pairs_figure as pairs_figure
from ._figures import pit_figure as pit_figure
from ._figures import ppc_figure as ppc_figure
from ._figures import where_figure as where_figure
from ._io import load_csv as load_csv
from ._io import load_netcdf as load_netcdf
from ._io import load_wide_csv as load_wide_csv
from ._io import load_measurement as load_measurement
from ._io import load_weight_arrays as load_weight_arrays
from ._io import save_csv as save_csv
from ._io import save_file as save_file
from ._io import save_netcdf as save_netcdf
from ._io import save_wide_csv as save_wide_csv
from ._io import save_measurement as save_measurement
from ._io import validate_arrays as validate_arrays
from ._localise import Residuals as Residuals
from ._offset_prior import prior_check as prior_check
from ._offset_prior import refusing as refusing
from ._localise import residuals as residuals
from ._localise import signatures as signatures
from ._localise import where_it_fails as where_it_fails
from ._shots import Model as Model
from ._shots import model_shots as model_shots
