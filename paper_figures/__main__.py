"""``python -m paper_figures``: run every sweep and draw every figure (see :mod:`paper_figures._build`)."""

from ._build import main

raise SystemExit(main())
