"""``tpnet demo``: the built-in rendered scene through the pipeline - pictures and a report (``tpnet_gpu.demo``)."""

from __future__ import annotations

import argparse

from tpnet_gpu.cli.common import BACKEND_HELP, DEVICE_HELP, NO_FIGURES_HELP, OVERWRITE_HELP, WEIGHTS_HELP, \
    default, one_shot_threads


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.demo import run_demo  # noqa: PLC0415 - torch, Warp and the renderer on use

    with one_shot_threads(args.height, args.width):
        report = run_demo(args.out, width=args.width, height=args.height, seed=args.seed, device=args.device,
                          backend=args.backend, weights=args.weights, figures=not args.no_figures,
                          overwrite=args.overwrite)
    print(report["text"])
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    from tpnet_gpu.config import BACKENDS  # noqa: PLC0415 - light: numpy only
    from tpnet_gpu.demo.run import run_demo  # noqa: PLC0415 - light: its heavy imports are inside it

    demo = sub.add_parser("demo", help="the built-in rendered scene through the pipeline: pictures + report")
    demo.add_argument("--out", default=default(run_demo, "out"),
                      help="output folder (an earlier demo's output there is refreshed)")
    demo.add_argument("--width", type=int, default=default(run_demo, "width"), help="frame width, px (multiple of 8)")
    demo.add_argument("--height", type=int, default=default(run_demo, "height"),
                      help="frame height, px (multiple of 8)")
    demo.add_argument("--seed", type=int, default=default(run_demo, "seed"), help="seed of the scene and the noise")
    demo.add_argument("--device", default=None, help=DEVICE_HELP)
    demo.add_argument("--backend", choices=BACKENDS, default=None, help=BACKEND_HELP)
    demo.add_argument("--weights", default=None, metavar="FILE", help=WEIGHTS_HELP)
    demo.add_argument("--no-figures", action="store_true", help=NO_FIGURES_HELP)
    demo.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    demo.set_defaults(func=run)
    return demo
