"""``gift train``: train an ONN in silico at noise level s0 (or load it from the cache)."""

from __future__ import annotations

from ._common import (add_data_arguments, arch_arg, check_data_folder, default_arch, nonneg_float, nonneg_int,
                      positive_float, positive_int)


def add_arguments(parser) -> None:
    add_data_arguments(parser)
    parser.add_argument("--arch", type=arch_arg, default=None, help="widths, e.g. 64-32-32-10 (default by dataset)")
    parser.add_argument("--activation", default="tanh", help="activation (tanh, identity, sigmoid, sin)")
    parser.add_argument("--s0", type=nonneg_float, default=0.1, help="assumed noise level (default 0.1)")
    parser.add_argument("--seed", type=nonneg_int, default=0,
                        help="names the initialisation and the sampling; part of the cache key (default 0)")
    parser.add_argument("--method", default="minibatch", choices=("minibatch", "projected_sgd", "optax"),
                        help="minibatch: the paper's practice (default); projected_sgd: eq. projected-sgd, one sample "
                             "per step, projected onto the box H; optax: an optax optimiser")
    parser.add_argument("--epochs", type=positive_int, default=None,
                        help="passes over the training set (minibatch, optax; default by data set)")
    parser.add_argument("--steps", type=positive_int, default=None, help="single-sample steps (projected_sgd)")
    parser.add_argument("--lr", type=positive_float, default=None, help="step size / learning rate (default by data set)")
    parser.add_argument("--batch-size", type=positive_int, default=None, help="mini-batch size (default 32)")
    parser.add_argument("--force", action="store_true", help="retrain even if cached")
    parser.add_argument("--out", default=None, metavar="FILE", help="also copy the weights to FILE (.npz)")


def run(args) -> dict:
    import dataclasses

    from .._arch import Architecture
    from ..training import default_config, load_or_train, save_weights

    check_data_folder(args)
    arch = args.arch or default_arch(args.dataset)
    arch = Architecture(arch.widths, args.activation)
    config = default_config(args.dataset, arch)
    changes = {k: v for k, v in (("method", args.method), ("epochs", args.epochs), ("steps", args.steps),
                                 ("lr", args.lr), ("batch_size", args.batch_size)) if v is not None}
    config = dataclasses.replace(config, **changes)
    params, info = load_or_train(args.dataset, arch, args.s0, args.seed, config=config, folder=args.data_folder,
                                 force=args.force, progress=True)
    if args.out:
        save_weights(args.out, params, {k: v for k, v in info.items() if k not in ("path", "cached")})
        info["out"] = args.out
    keys = ("dataset", "arch", "s0", "seed", "method", "steps", "path", "cached", "train_seconds",
            "train_loss", "train_accuracy", "test_loss", "test_accuracy", "train_examples", "test_examples")
    return {k: info.get(k) for k in keys} | ({"out": info["out"]} if "out" in info else {})


#: the standard MNIST's training and test images: a folder with fewer is said so
MNIST_SIZES = (60000, 10000)


def render(r: dict) -> str:
    src = "cache" if r["cached"] else f"trained in {r['train_seconds']:.1f} s"
    n, m = r.get("train_examples"), r.get("test_examples")
    size = f", {n} training / {m} test examples" if n is not None else ""
    note = ""
    if r["dataset"] == "mnist" and n is not None and (n, m) != MNIST_SIZES:
        note = (f"\n  note: the folder holds {n} training and {m} test images, not MNIST's {MNIST_SIZES[0]} and "
                f"{MNIST_SIZES[1]}: a subset, or not the folder meant?")
    return (f"{r['dataset']} {r['arch']} at s0={r['s0']:g}, seed {r['seed']} ({src}{size}){note}\n"
            f"  train: loss {r['train_loss']:.4f}  accuracy {100 * r['train_accuracy']:.2f} %\n"
            f"  test:  loss {r['test_loss']:.4f}  accuracy {100 * r['test_accuracy']:.2f} %\n"
            f"  weights: {r['path'] or 'not kept (the cache could not be written)'}"
            + (f"\n  copied to: {r['out']}" if r.get("out") else ""))
