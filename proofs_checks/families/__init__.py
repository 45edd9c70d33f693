"""Example J_s families for ``gift check theorem1 --family FILE.py`` (reference §5b).

Each file defines ``s``, ``w``, ``J``, ``w0`` (sympy) or ``J(w, s)``, ``w0`` (numeric);
:func:`path` returns a file's location, e.g. ``gift check theorem1 --family
$(python -c "import proofs_checks.families as f; print(f.path('quartic'))") --s0 1 --st 1.1``.
"""

import os

NAMES = ("quartic", "counterexample", "linear_chain", "onn_tanh", "per_sample")


def path(name: str) -> str:
    """The file of the example family ``name`` (one of :data:`NAMES`)."""
    if name not in NAMES:
        raise ValueError(f"unknown family {name!r}; known: {', '.join(NAMES)}")
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), f"{name}.py")
