"""Devices: the Chip protocol, the shot ledger, and a simulated chip with hidden physics.

See ``docs/hardware.md`` for wrapping real hardware in the same protocol.
"""

from ._base import BudgetExceeded as BudgetExceeded
from ._base import Chip as Chip
from ._base import Ledger as Ledger
from .._measurement import Measurement as Measurement
from ._base import chip_eval as chip_eval
from ._simulated import SimulatedChip as SimulatedChip
from ._simulated import simulate_measurement as simulate_measurement
from ._user import CheckedChip as CheckedChip
from ._user import chip_scores as chip_scores
from ._user import load_chip as load_chip
from ._user import uncharged as uncharged
