"""The sweeps behind the figures, at three scales.

* ``quick`` -- digits (8x8, 1437 train / 360 test), a deeper 64-48-32-32-16-10 and a shallower
  64-32-32-10 net, 2 seeds, s0, st in {0.05, 0.1, 0.2} (under-estimation s0 < st, over-
  estimation s0 > st and s0 = st): minutes on 2 cores.
* ``paper`` -- the paper's 784-500-250-250-100-50-10 and 784-500-100-100-10 on mnist5k (or full
  MNIST with an IDX folder), 10 seeds per s0 as in the paper, our grid s0, st in {0.02, 0.05,
  0.1, 0.15, 0.2} (the paper names no noise values), extended on the deeper net to st up to
  0.4 (issue 25) and to s0 = 0.01, st up to 0.8 (issue 47, 5 seeds).
* ``paper-subset`` -- the paper's nets on mnist5k with 3 seeds, s0, st in {0.05, 0.1, 0.2};
  the violated-noise laws and the rivals (identify-retrain included) at the two misspecified
  pairs s0 = 0.1, st in {0.05, 0.2}: what this 2-core machine can run in hours.
* ``tiny`` -- a few points of every sweep, for the test suite.

Every figure script names the sweeps it reads (``SWEEPS``); :func:`sweeps` builds them.
"""

from __future__ import annotations

import dataclasses

from ._sweep import Sweep

RIVALS = ("gift", "gift-printed", "pathwise", "ift", "gradient", "random", "spsa", "pat", "identify-retrain",
          "retrain")

#: the variants sweep's names (:data:`paper_figures._jobs.VARIANTS` but plain gift, which the
#: GIFT sweeps already hold at every cell)
VARIANT_NAMES = ("gift-noconfirm", "gift-budget100", "printed-eta0.05", "printed-eta0.1", "printed-eta0.3",
                 "printed-eta1", "printed-w0-eta0.05", "printed-w0-eta0.1", "printed-w0-eta0.3", "printed-w0-eta1",
                 "retrain", "retrain-s0")


@dataclasses.dataclass(frozen=True)
class Scale:
    """Everything that differs between scales."""

    name: str
    dataset: str
    nets: dict                      # label -> architecture string
    seeds: tuple
    s0: tuple
    st: tuple
    violated_s0: tuple
    violated_st: tuple
    rival_methods: tuple
    rival_s0: tuple
    rival_st: tuple
    rival_seeds: tuple
    est_arch: str
    est_K1: tuple
    est_K2: tuple
    est_reps: int
    est_methods: tuple = ("score_paper", "score", "pathwise", "fd")
    est_ref_K2: int = 64
    est_train_epochs: int | None = None
    options: dict = dataclasses.field(default_factory=dict)
    # issue 25: the regime where the deeper net's baseline collapses, the ceiling of the GIFT
    # line, the variants at key cells, and the under-trained w0
    regime_s0: tuple = ()
    regime_st: tuple = ()
    regime_rival_methods: tuple = ()
    regime_rival_s0: tuple = ()
    regime_rival_seeds: tuple = ()
    regime_rival_st: tuple = ()     # () : regime_st
    ceiling_kinds: tuple = ("pathwise", "score_paper")
    ceiling_s0: tuple = ()          # () : the GIFT grid's
    ceiling_st: tuple = ()
    ceiling_seeds: tuple = ()
    variants: tuple = ()
    variant_s0: tuple = ()
    variant_st: tuple = ()
    variant_seeds: tuple = ()
    under_methods: tuple = ("gift", "gradient")
    under_epochs: tuple = ()
    under_s0: tuple = ()
    under_st: tuple = ()
    under_seeds: tuple = ()
    #: (s0, st) cells run first by ``--cells key`` (the most informative: where the baseline is lowest)
    key_cells: tuple = ()
    # issue 47: our grid extended where relative gains inflate (smaller s0, larger st): the methods
    # of ``extended`` (finetune methods or names of _jobs.VARIANTS) and ``ceiling_extended``
    ext_methods: tuple = ()
    ext_s0: tuple = ()
    ext_st: tuple = ()
    ext_seeds: tuple = ()


SCALES = {
    "quick": Scale(
        name="quick", dataset="digits",
        nets={"deep": "64-48-32-32-16-10", "shallow": "64-32-32-10"},
        seeds=(0, 1), s0=(0.05, 0.1, 0.2), st=(0.05, 0.1, 0.2),
        violated_s0=(0.05, 0.1, 0.2), violated_st=(0.05, 0.1, 0.2),
        rival_methods=RIVALS, rival_s0=(0.1,), rival_st=(0.05, 0.2), rival_seeds=(0, 1),
        est_arch="64-32-32-10", est_K1=(32, 128, 512), est_K2=(2, 16), est_reps=3),
    "paper": Scale(
        name="paper", dataset="mnist5k",
        nets={"deep": "784-500-250-250-100-50-10", "shallow": "784-500-100-100-10"},
        seeds=tuple(range(10)), s0=(0.02, 0.05, 0.1, 0.15, 0.2), st=(0.02, 0.05, 0.1, 0.15, 0.2),
        violated_s0=(0.02, 0.05, 0.1, 0.15, 0.2), violated_st=(0.02, 0.05, 0.1, 0.15, 0.2),
        rival_methods=RIVALS, rival_s0=(0.05, 0.1, 0.2), rival_st=(0.05, 0.1, 0.2), rival_seeds=tuple(range(10)),
        est_arch="784-500-250-250-100-50-10", est_K1=(64, 256, 1024, 4096), est_K2=(2, 8, 32), est_reps=5,
        regime_s0=(0.02, 0.05, 0.1, 0.2), regime_st=(0.25, 0.3, 0.4),
        regime_rival_methods=RIVALS, regime_rival_s0=(0.02,), regime_rival_seeds=(0, 1, 2),
        regime_rival_st=(0.2, 0.25, 0.3, 0.4),  # 0.2: GIFT's best cell on our grid (s0, st <= 0.2)
        variants=VARIANT_NAMES, variant_s0=(0.02, 0.1), variant_st=(0.2, 0.3), variant_seeds=tuple(range(10)),
        under_epochs=(5, 30), under_s0=(0.02, 0.1), under_st=(0.1, 0.2), under_seeds=tuple(range(5)),
        key_cells=((0.02, 0.2), (0.02, 0.25), (0.02, 0.3), (0.02, 0.4)),
        # identify-retrain last: it is most of the job time (~10 min a point)
        ext_methods=("gift", "gift-noconfirm", "pathwise", "retrain", "identify-retrain"), ext_s0=(0.01, 0.02),
        ext_st=(0.5, 0.6, 0.8), ext_seeds=tuple(range(5))),
    # the paper's nets and data at 3 seeds, the violated laws and the rivals at two misspecified
    # pairs (under- and over-estimation of the noise, one in-silico training per seed)
    "paper-subset": Scale(
        name="paper-subset", dataset="mnist5k",
        nets={"deep": "784-500-250-250-100-50-10", "shallow": "784-500-100-100-10"},
        seeds=(0, 1, 2), s0=(0.05, 0.1, 0.2), st=(0.05, 0.1, 0.2),
        violated_s0=(0.1,), violated_st=(0.05, 0.2),
        rival_methods=RIVALS, rival_s0=(0.1,), rival_st=(0.05, 0.2), rival_seeds=(0, 1, 2),
        est_arch="784-500-250-250-100-50-10", est_K1=(64, 256, 1024), est_K2=(2, 8), est_reps=2),
    "tiny": Scale(
        name="tiny", dataset="digits",
        nets={"deep": "64-12-10-10-10", "shallow": "64-12-10"},
        seeds=(0, 1), s0=(0.1, 0.2), st=(0.1, 0.2),
        violated_s0=(0.1,), violated_st=(0.2,),
        rival_methods=("gift", "random"), rival_s0=(0.1,), rival_st=(0.2,), rival_seeds=(0,),
        est_arch="64-12-10", est_K1=(16, 64), est_K2=(2,), est_reps=1, est_methods=("pathwise", "score"),
        est_ref_K2=8, options={"budget": 6, "referee_K2": 4},
        ceiling_s0=(0.1,), ceiling_st=(0.2,), ceiling_seeds=(0,),
        regime_s0=(0.1,), regime_st=(0.3,), regime_rival_methods=("gift", "retrain"), regime_rival_s0=(0.1,),
        regime_rival_seeds=(0,), variants=("gift-noconfirm", "printed-w0-eta0.1", "retrain", "retrain-s0"),
        variant_s0=(0.1,), variant_st=(0.2,), variant_seeds=(0, 1),
        under_epochs=(2, 30), under_s0=(0.1,), under_st=(0.2,), under_seeds=(0, 1),
        key_cells=((0.1, 0.2),),
        ext_methods=("gift", "gift-noconfirm"), ext_s0=(0.1,), ext_st=(0.35,), ext_seeds=(0,)),
}


def get_scale(name: str) -> Scale:
    if name not in SCALES:
        raise ValueError(f"scale {name!r} unknown; known: {', '.join(SCALES)}")
    return SCALES[name]


def _gift_fixed(scale: Scale, mnist_folder: str | None, options: dict | None) -> dict:
    opts = dict(scale.options, **(options or {}))
    dataset = scale.dataset
    if mnist_folder:
        dataset = "mnist"
        opts["data_folder"] = mnist_folder  # run_finetune's name for the IDX folder
    return {"dataset": dataset, "options": opts}


def sweeps(scale: Scale | str, *, mnist_folder: str | None = None, options: dict | None = None) -> dict[str, Sweep]:
    """All sweeps of a scale by name.

    ``gift_awgn``: GIFT under AWGN, dims (net, s0, st, seed) -- fig:performance_gift,
    fig:performance_gift_shallow, fig:performance_gift_test_data, fig:abs_performance_gift.
    ``gift_violated``: GIFT on the deeper net, true noise laplace / multiplicative / uniform,
    dims (noise_kind, s0, st, seed) -- fig:performance_gift_violated_noise_assumption,
    fig:performance_gift_test_data_violated_awgn.
    ``rivals``: every finetune method on the shallower net, dims (method, s0, st, seed).
    ``estimators``: d/ds grad J estimators, dims (method, K1, K2, rep).

    Issue 25 (when the scale defines them): ``gift_regime`` (GIFT on the deeper net at the
    extended st where its baseline collapses, dims s0, st, seed); ``rivals_regime`` (the
    rivals on the deeper net there, and at st = 0.2 where our grid ends); ``ceiling_deep`` / ``ceiling_shallow`` (the referee's best
    along the GIFT line, pathwise and printed direction, at every point of the GIFT grid and
    the extended st); ``variants`` (gift without confirmation or with a 5x budget,
    gift-printed with and without w0 at eta in {0.05, 0.1, 0.3, 1} % of |w0|, the retrain
    oracle and its control at s0; dims variant, s0, st, seed); ``undertrained`` and
    ``undertrained_ceiling`` (gift and the gradient line search, and their lines' ceilings
    with the cosine of the two directions, for w0 trained ``train_epochs``).

    Issue 47: ``extended`` (the deeper net where relative gains inflate, s0 in {0.01, 0.02} x
    st in {0.5, 0.6, 0.8}: gift, gift without confirmation, Algorithm 1 with the pathwise
    direction, the retrain oracle and identify-retrain; dims method, s0, st, seed) and
    ``ceiling_extended`` (the ceiling of GIFT's line there, pathwise direction only).
    """
    scale = get_scale(scale) if isinstance(scale, str) else scale
    fixed = _gift_fixed(scale, mnist_folder, options)
    job = "paper_figures._jobs:gift_job"
    out = {}
    # one sweep per net so that the arch string travels with the point (it is a function of net)
    for net, arch in scale.nets.items():
        out[f"gift_awgn_{net}"] = Sweep(f"gift_awgn_{net}", {"s0": scale.s0, "st": scale.st, "seed": scale.seeds},
                                        job, dict(fixed, net=net, arch=arch, noise_kind="awgn", method="gift"))
    out["gift_violated"] = Sweep(
        "gift_violated", {"noise_kind": ("laplace", "multiplicative", "uniform"), "s0": scale.violated_s0,
                          "st": scale.violated_st, "seed": scale.seeds},
        job, dict(fixed, net="deep", arch=scale.nets["deep"], method="gift"))
    out["rivals"] = Sweep(
        "rivals", {"method": scale.rival_methods, "s0": scale.rival_s0, "st": scale.rival_st,
                   "seed": scale.rival_seeds},
        job, dict(fixed, net="shallow", arch=scale.nets["shallow"], noise_kind="awgn"))
    deep = dict(fixed, net="deep", arch=scale.nets["deep"], noise_kind="awgn")
    ceil = "paper_figures._jobs:ceiling_job"
    if scale.regime_st:
        out["gift_regime"] = Sweep("gift_regime", {"s0": scale.regime_s0, "st": scale.regime_st, "seed": scale.seeds},
                                   job, dict(deep, method="gift"))
        out["rivals_regime"] = Sweep(
            "rivals_regime", {"method": scale.regime_rival_methods, "s0": scale.regime_rival_s0,
                              "st": scale.regime_rival_st or scale.regime_st, "seed": scale.regime_rival_seeds},
            job, deep)
    for net, arch in scale.nets.items():
        sts = tuple(scale.ceiling_st or scale.st) + (tuple(scale.regime_st) if net == "deep" else ())
        out[f"ceiling_{net}"] = Sweep(f"ceiling_{net}", {"s0": scale.ceiling_s0 or scale.s0, "st": sts,
                                                         "seed": scale.ceiling_seeds or scale.seeds}, ceil,
                                      dict(fixed, net=net, arch=arch, noise_kind="awgn", kinds=scale.ceiling_kinds))
    if scale.variants:
        out["variants"] = Sweep("variants", {"variant": scale.variants, "s0": scale.variant_s0, "st": scale.variant_st,
                                             "seed": scale.variant_seeds}, job, deep)
    if scale.ext_methods:
        # methods first in the dims: a single worker runs them in this order (identify-retrain last)
        out["extended"] = Sweep("extended", {"method": scale.ext_methods, "s0": scale.ext_s0, "st": scale.ext_st,
                                             "seed": scale.ext_seeds}, job, deep)
        out["ceiling_extended"] = Sweep("ceiling_extended", {"s0": scale.ext_s0, "st": scale.ext_st,
                                                             "seed": scale.ext_seeds}, ceil,
                                        dict(deep, kinds=("pathwise",)))
    if scale.under_epochs:
        out["undertrained"] = Sweep(
            "undertrained", {"method": scale.under_methods, "train_epochs": scale.under_epochs, "s0": scale.under_s0,
                             "st": scale.under_st, "seed": scale.under_seeds}, job, deep)
        out["undertrained_ceiling"] = Sweep(
            "undertrained_ceiling", {"train_epochs": scale.under_epochs, "s0": scale.under_s0, "st": scale.under_st,
                                     "seed": scale.under_seeds}, ceil,
            dict(deep, kinds=("pathwise", "score_paper", "gradient")))
    out["estimators"] = Sweep(
        "estimators", {"method": scale.est_methods, "K1": scale.est_K1, "K2": scale.est_K2,
                       "rep": tuple(range(scale.est_reps))},
        "paper_figures._jobs:estimator_job",
        {"dataset": "digits" if scale.dataset == "digits" else scale.dataset, "arch": scale.est_arch,
         "s0": 0.1, "seed": 0, "ref_K2": scale.est_ref_K2,
         **({} if scale.est_train_epochs is None else {"train_epochs": scale.est_train_epochs})})
    return out
