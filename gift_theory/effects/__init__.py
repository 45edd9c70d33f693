"""The physical effects of CONTRACTS §2, one module each, and their composition.

=================  ==================  ==========================================
name               parameters          module
=================  ==================  ==========================================
awgn               s                   :mod:`.awgn`
laplace            (uses s)            :mod:`.laplace`
uniform            (uses s)            :mod:`.uniform`
multiplicative     m                   :mod:`.multiplicative`
common_mode        c                   :mod:`.common_mode`
drift              r                   :mod:`.drift`
crosstalk          k                   :mod:`.crosstalk`
weight_error       e (device: seed)    :mod:`.weight_error`
shot               q                   :mod:`.shot`
saturation         v_max               :mod:`.saturation`
quantization       bits, v_range       :mod:`.quantization`
=================  ==================  ==========================================
"""

from ._base import REGISTRY as REGISTRY
from ._base import Effect as Effect
from ._base import make_effect as make_effect
from ._base import parse_effect as parse_effect
from ._physics import Physics as Physics
from ._physics import awgn as awgn
from .awgn import Awgn as Awgn
from .common_mode import CommonMode as CommonMode
from .crosstalk import Crosstalk as Crosstalk
from .drift import Drift as Drift
from .laplace import Laplace as Laplace
from .multiplicative import Multiplicative as Multiplicative
from .quantization import Quantization as Quantization
from .saturation import Saturation as Saturation
from .shot import Shot as Shot
from .uniform import Uniform as Uniform
from .weight_error import WeightError as WeightError

#: the CONTRACTS §2 names, in catalogue order
EFFECT_NAMES = ("awgn", "laplace", "uniform", "multiplicative", "common_mode", "drift",
                "crosstalk", "weight_error", "shot", "saturation", "quantization")
assert set(EFFECT_NAMES) == set(REGISTRY), "effect registry and catalogue disagree"
