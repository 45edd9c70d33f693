"""Issue 25's sweeps at paper scale, the most informative points first, in resumable pieces.

    python -m paper_figures.key_first [--workers N]

Order: ``gift_regime`` at s0 = 0.02 (the cells where the deeper net's baseline collapses),
the retrain oracle and its control at s0 (``retrain``, ``retrain-s0``) at (0.02, 0.2) and
(0.02, 0.3), ``gift-noconfirm`` and ``printed-w0-eta0.1`` there, then the rest of
``gift_regime``. Each point is saved as it lands (point ids do not depend on the grid, so the
full sweeps later skip them); the partial ``variants.nc`` is assembled after the variants and
``gift_regime.nc`` at the end. The ceilings' key cells run by
``python -m paper_figures --scale paper --only ceiling --cells key``.
"""

from __future__ import annotations

import argparse

from ._scales import sweeps
from ._sweep import assemble, restrict, run_sweep, save_dataset

FOLDER = "paper_figures/data/paper"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m paper_figures.key_first", description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    ap.add_argument("--data-dir", default=FOLDER, help=f"where the sweep data go (default {FOLDER})")
    args = ap.parse_args(argv)
    S = sweeps("paper")
    run_sweep(restrict(S["gift_regime"], s0=(0.02,)), args.data_dir, n_workers=args.workers, save=False)
    for variants in (("retrain", "retrain-s0"), ("gift-noconfirm", "printed-w0-eta0.1")):
        for st in (0.2, 0.3):
            run_sweep(restrict(S["variants"], variant=variants, s0=(0.02,), st=(st,)), args.data_dir,
                      n_workers=args.workers, save=False)
    save_dataset(assemble(args.data_dir, S["variants"]), f"{args.data_dir}/variants.nc")
    run_sweep(S["gift_regime"], args.data_dir, n_workers=args.workers)


if __name__ == "__main__":
    main()
