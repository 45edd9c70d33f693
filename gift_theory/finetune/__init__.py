"""Fine-tuning against a chip: Algorithm 1 as printed, the repaired GIFT, and the rivals.

``run_finetune`` is the library form of ``gift finetune``; ``compare_methods`` runs many
methods on one setting (used by ``gift demo`` and the report's grid); ``run_ceiling`` is the
referee's best along a line search's line (the most any search along it could give).
"""

from ._ceiling import CEILING_DIRECTIONS as CEILING_DIRECTIONS
from ._ceiling import line_ceiling as line_ceiling
from ._ceiling import run_ceiling as run_ceiling
from ._directions import DIRECTIONS as DIRECTIONS
from ._directions import conjugate_gradients as conjugate_gradients
from ._directions import direction as direction
from ._linesearch import fit_quadratic as fit_quadratic
from ._linesearch import gift_printed as gift_printed
from ._linesearch import paired_line_search as paired_line_search
from ._linesearch import why as why
from ._problem import Problem as Problem
from ._problem import make_problem as make_problem
from ._problem import referee as referee
from ._problem import referee_losses as referee_losses
from ._rivals import RETRAIN as RETRAIN
from ._rivals import identify_noise_level as identify_noise_level
from ._rivals import identify_physics as identify_physics
from ._rivals import identify_retrain as identify_retrain
from ._rivals import pat as pat
from ._rivals import retrain as retrain
from ._rivals import spsa as spsa
from ._run import GRID as GRID
from ._run import METHODS as METHODS
from ._run import RUNNERS as RUNNERS
from ._run import oracle_grid as oracle_grid
from ._run import true_physics as true_physics
from ._run import compare_methods as compare_methods
from ._run import finetune_on as finetune_on
from ._run import load_setting as load_setting
from ._run import run_finetune as run_finetune
