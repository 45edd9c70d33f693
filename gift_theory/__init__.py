"""gift_theory: the core of gift.

The paper's ONN model M_s with the physical effects of reference §2, Monte-Carlo
objectives with standard errors, in-silico training and data sets. Subpackages hold the
larger parts: :mod:`gift_theory.effects`, :mod:`gift_theory.data`,
:mod:`gift_theory.training`.

Importing the package changes no process-wide setting. :func:`use_compilation_cache` is the
explicit opt-in to JAX's persistent compilation cache (the ``gift`` command and the sweep
workers call it): compiled programs then persist on disk across processes.
"""

from ._arch import ACTIVATIONS as ACTIVATIONS
from ._arch import Architecture as Architecture
from ._errors import GiftInputError as GiftInputError
from ._measurement import Measurement as Measurement
from ._model import Forward as Forward
from ._model import forward as forward
from ._model import sample_noise as sample_noise
from ._model import simulate as simulate
from ._model import squared_error as squared_error
from ._objective import Estimate as Estimate
from ._objective import accuracy as accuracy
from ._objective import estimate_from_samples as estimate_from_samples
from ._objective import eval_from_outputs as eval_from_outputs
from ._objective import objective as objective
from ._objective import paired_difference as paired_difference
from ._objective import per_input_loss as per_input_loss
from ._params import Box as Box
from ._params import Layer as Layer
from ._params import cast as cast_params
from ._params import arch_of as arch_of
from ._params import check_params as check_params
from ._params import flatten as flatten
from ._params import init_params as init_params
from ._params import params_from_arrays as params_from_arrays
from ._params import params_to_arrays as params_to_arrays
from ._params import project as project
from .effects import EFFECT_NAMES as EFFECT_NAMES
from .effects import Physics as Physics
from .effects import awgn as awgn
from .effects import make_effect as make_effect
from .effects import parse_effect as parse_effect

from ._io import atomic_path as atomic_path
from ._io import atomic_write as atomic_write
from ._io import atomic_write_bytes as atomic_write_bytes
from ._io import atomic_write_text as atomic_write_text
from ._io import save_figure as save_figure
from ._xla import use_compilation_cache as use_compilation_cache

__version__ = "0.1.0"

#: subpackages, imported on first use (``gt.estimators``, ``gt.lab``, ...) to keep start-up fast
_SUBPACKAGES = ("chips", "data", "effects", "estimators", "finetune", "lab", "training")


def __getattr__(name):
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_SUBPACKAGES))
