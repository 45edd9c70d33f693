"""proofs_checks: every claim of the paper as a computed verdict (CONTRACTS §4-5).

``run_checks()`` runs the twelve checks of CONTRACTS §5 and returns their records
``{id, claim, verdict, evidence, correction, counterexample}``; ``theorem1_check`` is the
user-facing Theorem 1 checker for one's own model, data and trained weights.
"""

from ._gift import algorithm1 as algorithm1
from ._record import VERDICTS as VERDICTS
from ._record import equality_verdict as equality_verdict
from ._record import record as record
from ._record import sign_verdict as sign_verdict
from ._registry import CHECK_IDS as CHECK_IDS
from ._registry import CHECKS as CHECKS
from ._registry import run_checks as run_checks
from ._report import render_markdown as render_markdown
from ._report import render_table as render_table
from ._report import write_report as write_report
from ._theorem1 import render_theorem1 as render_theorem1
from ._theorem1 import theorem1_check as theorem1_check
