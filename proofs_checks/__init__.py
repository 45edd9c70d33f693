"""proofs_checks: every claim of the paper as a computed verdict (CONTRACTS §4-5)."""

from ._record import record as record
from ._theorem1 import render_theorem1 as render_theorem1
from ._theorem1 import theorem1_check as theorem1_check
