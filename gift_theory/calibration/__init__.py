"""Calibration: from what the chip realises to weights that make it realise the trained network.

:func:`fit_layers` reads each layer's realised map off a measurement (taps: every layer; no taps:
the output); :func:`calibrate` is the fine-tuning method (``gift finetune --method calibrate``):
measure, fit, pin what is stuck, retrain the target under the identified device, pre-compensate,
measure again, and confirm on the chip.
"""

from ._fit import LayerMap as LayerMap
from ._fit import fit_layers as fit_layers
from ._loop import calibrate as calibrate
from ._loop import noise_physics as noise_physics
from ._file import FileCalibration as FileCalibration
from ._file import calibrate_measurement as calibrate_measurement
from ._model import ChipModel as ChipModel
from ._model import LayerResponse as LayerResponse
from ._model import load_chip_model as load_chip_model
