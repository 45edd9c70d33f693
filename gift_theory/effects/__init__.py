"""The physical effects of reference §2 and §2b, one module each, their composition, and
the open catalogue (effects a user adds).

=================  ======================  ==============  =====================  ======================
name               parameters              stage           mechanism (§6)         module
=================  ======================  ==============  =====================  ======================
awgn               s                       level           noise_level            :mod:`.awgn`
laplace            (uses s)                law             noise_law              :mod:`.laplace`
uniform            (uses s)                law             noise_law              :mod:`.uniform`
multiplicative     m                       gain            input_dependent_noise  :mod:`.multiplicative`
common_mode        c                       gain            gain_fluctuation       :mod:`.common_mode`
drift              r                       gain            time_drift             :mod:`.drift`
crosstalk          k                       weights         weight_error           :mod:`.crosstalk`
weight_error       e (device: seed)        weights         weight_error           :mod:`.weight_error`
shot               q                       readout         input_dependent_noise  :mod:`.shot`
saturation         v_max                   readout         readout_nonlinearity   :mod:`.saturation`
quantization       bits, v_range           readout         readout_nonlinearity   :mod:`.quantization`
bias_offset        sigma (device: seed)    bias            bias_offset            :mod:`.bias_offset`
activation_gain    kappa (hidden layers)   activation      activation_mismatch    :mod:`.activation_gain`
layer_gain         g (one per layer)       weights         gain_error             :mod:`.layer_gain`
memory             alpha (needs t)         readout         memory                 :mod:`.memory`
=================  ======================  ==============  =====================  ======================

The first eleven are reference §2's original table (:data:`EFFECT_NAMES`); :data:`BUILTIN`
lists all fifteen built-in ones (the §2 table now lists every one of them). A user adds an
effect in a file of their own (reference §2b)::

    from gift_theory.effects import Effect, register

    @register
    class ActGain(Effect):
        kappa: float = 1.0
        name = "act_gain"
        params = ("kappa",)
        bounds = {"kappa": (0.2, 5.0)}
        defaults = {"kappa": 1.0}
        stage = "activation"
        layers = "hidden"
        mechanism = "activation_mismatch"
        description = "the chip's nonlinearity is sigma(kappa z)"

        def activation(self, z, sigma, layer):
            return sigma(self.kappa * z)

and loads it with :func:`load_plugin` (``gift ... --plugin FILE.py``) or through the
entry-point group ``gift.effects`` (:func:`load_entry_points`); its name is then used like
any built-in one.

Public API
----------
:class:`Effect`, :func:`register`, :data:`REGISTRY`, :data:`STAGES`, :data:`MECHANISMS`,
:data:`BUILTIN`, :data:`EFFECT_NAMES`, :class:`Physics`, :func:`awgn`, :func:`make_effect`,
:func:`parse_effect`, :func:`load_plugin`, :func:`load_entry_points`.
"""

from ._base import MECHANISMS as MECHANISMS
from ._base import REGISTRY as REGISTRY
from ._base import STAGES as STAGES
from ._base import Effect as Effect
from ._base import make_effect as make_effect
from ._base import parse_effect as parse_effect
from ._base import register as register
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
from .bias_offset import BiasOffset as BiasOffset
from .activation_gain import ActivationGain as ActivationGain
from .layer_gain import LayerGain as LayerGain
from .memory import Memory as Memory
from ._physics import Physics as Physics
from ._physics import awgn as awgn
from ._plugins import load_entry_points as load_entry_points
from ._plugins import load_plugin as load_plugin

#: the reference §2 names, in catalogue order (the effects the contract's table lists)
EFFECT_NAMES = ("awgn", "laplace", "uniform", "multiplicative", "common_mode", "drift",
                "crosstalk", "weight_error", "shot", "saturation", "quantization")

#: every built-in effect, in catalogue order: reference §2's first eleven, then the ones added since
BUILTIN = EFFECT_NAMES + ("bias_offset", "activation_gain", "layer_gain", "memory")

if set(BUILTIN) != set(REGISTRY):  # pragma: no cover - a module was added without listing it
    raise ImportError(f"effect registry and catalogue disagree: {sorted(set(BUILTIN) ^ set(REGISTRY))}")
