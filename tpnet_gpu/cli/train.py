"""``tpnet train``: TPNET trained on a data set from ``tpnet dataset`` (``tpnet_gpu.net.train``; checkpoints
resume)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tpnet_gpu.cli.common import DEVICE_HELP


def run(args: argparse.Namespace) -> int:
    import torch  # noqa: PLC0415

    from tpnet_gpu.net.train import TrainConfig, train  # noqa: PLC0415
    from tpnet_gpu.outputs import claimed_file  # noqa: PLC0415

    if not 1 <= args.threads <= 1024:  # torch's own refusal is a RuntimeError traceback
        raise ValueError(f"--threads: expected 1..1024 CPU threads, got {args.threads}")
    config = TrainConfig(epochs=args.epochs, batch=args.batch, seed=args.seed, w_mode=args.w_mode,
                         error_scale=args.error_scale or None,
                         variant_weights=tuple(args.random_weight if v == "random" else 1.0 for v in TrainConfig.variants),
                         init=args.init, lr_from=args.lr_from, pass_every=args.pass_every)
    torch.set_num_threads(args.threads)
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    rig = None
    if args.rig is not None:
        from tpnet_gpu.io import rigfile  # noqa: PLC0415

        rig = rigfile.load(args.rig)
    recipe = Path(args.out).with_suffix(".json")
    if recipe.exists() and not args.overwrite:  # the recipe beside the weights is theirs: both or neither
        raise ValueError(f"--out: expected new weights (or --overwrite), got {args.out}, whose recipe {recipe} exists")
    with claimed_file(args.out, overwrite=args.overwrite) as out:  # before the training, not after it
        result = train(args.data, out, config, checkpoint=args.checkpoint, device=device, rig=rig)
    last = result["history"][-1]
    print(f"trained {last['epoch']} epochs: loss {last['loss']:.5f}, test RMSE network {last['test_rmse_network']:.4f} "
          f"px vs its targets {last['test_rmse_target']:.4f} px -> {args.out}")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    from tpnet_gpu.config import TrainConfig  # noqa: PLC0415 - light: numpy only

    train = TrainConfig()
    tr = sub.add_parser("train", help="train TPNET on a data set (checkpoints resume)")
    tr.add_argument("data", help="data set folder (from `tpnet dataset`)")
    tr.add_argument("--out", default="out/tpnet.pt", help="final weights (a recipe .json is written beside)")
    tr.add_argument("--overwrite", action="store_true",
                    help="replace existing weights at --out and their recipe (default: refuse them, before training)")
    tr.add_argument("--rig", default=None, metavar="FILE",
                    help="the rig to train for (a rig file or a shipped one): must be the data set's rig (its layer "
                         "lags); the network always has one layer per direction group of the data set's rig")
    tr.add_argument("--checkpoint", default="out/tpnet_checkpoint.pt", help="checkpoint file (resumed if present)")
    tr.add_argument("--epochs", type=int, default=train.epochs)
    tr.add_argument("--batch", type=int, default=train.batch, help="frames per step")
    tr.add_argument("--seed", type=int, default=train.seed)
    tr.add_argument("--w-mode", choices=("as_coded", "isotropic"), default=train.w_mode,
                    help="Laplacian regulariser of the first layer (network.md §2)")
    tr.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    tr.add_argument("--device", default=None, help=DEVICE_HELP)
    tr.add_argument("--error-scale", type=float, default=train.error_scale,
                    help="c (px): errors are scaled by c / (|target - gt| + c); 0: plain errors, as the original")
    tr.add_argument("--random-weight", type=float, default=1.0,
                    help="loss weight of the random-offset (+-2 px) targets relative to the others")
    tr.add_argument("--init", default=None, metavar="WEIGHTS",
                    help="fine-tune: start from these weights (e.g. the shipped ones) instead of fresh ones")
    tr.add_argument("--lr-from", type=float, default=train.lr_from,
                    help="fraction of the learning-rate schedule the run starts at (fine-tuning: 0.3, from 3e-5)")
    tr.add_argument("--pass-every", type=int, default=train.pass_every, metavar="EPOCHS",
                    help="train on the network's own pass too: its prediction from the heuristic targets, re-measured "
                         "from the scenes' raw frames every EPOCHS epochs (a second pass converges instead of drifting)")
    tr.set_defaults(func=run)
    return tr
