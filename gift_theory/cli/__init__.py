"""The ``gift`` command: a thin shell that parses, calls the library, prints.

Commands of the core live here (``gift_theory.cli._<name>``); packages on top of gift register
theirs through the entry-point group ``gift.commands`` (``name = "package.module"``; the module
defines ``HELP``, ``add_arguments(parser)``, ``run(args)`` and optionally ``render(result)``) and
use this public API for what every command shares.
"""

from ._common import Progress as Progress
from ._common import REFERENCE as REFERENCE
from ._common import did_you_mean as did_you_mean
from ._common import nonneg_float as nonneg_float
from ._common import nonneg_int as nonneg_int
from ._common import positive_float as positive_float
from ._common import positive_int as positive_int
from ._fit import standouts as standouts
from ._main import emit as emit
from ._main import main as main
