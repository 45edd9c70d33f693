"""proofs_checks: every claim of the paper as a computed verdict (reference §4-5).

``run_checks()`` runs the registered checks (the twelve of reference §5, then the ids appended
by issue 12) and returns their records ``{id, claim, verdict, evidence, correction,
counterexample, hypotheses}``. ``theorem1`` checks Theorem 1 on any J_s family (sympy or
numeric; reference §5b), ``theorem1_check`` on one's own model, data and trained weights.
"""

from ._family import Family as Family
from ._family import FamilyError as FamilyError
from ._family import family as family
from ._family import load_family as load_family
from ._family_check import contract_json as contract_json
from ._family_check import render as render_family_result
from ._family_check import theorem1 as theorem1
from ._gift import algorithm1 as algorithm1
from ._record import FAMILY_ALPHA as FAMILY_ALPHA
from ._record import VERDICTS as VERDICTS
from ._record import equality_verdict as equality_verdict
from ._record import level as level
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
