"""The ``tpnet`` command line. Each subcommand has ``--help``; bad input ends with a one-line message, not a
traceback (exit status 2). ``demo``, ``process`` and ``render`` write their output folder whole or not at all and
refuse a non-empty one without ``--overwrite`` (``tpnet_gpu.outputs``; ``demo`` refreshes its own earlier output).

One module per subcommand (``cli/NAME.py``: ``add_parser(sub)`` and ``run(args)``); ``cli/ray.py`` adds the Ray
options to ``process`` and ``dataset``; ``cli/common.py`` holds what they share. Every option whose value the
library also defaults takes the library's default."""

from __future__ import annotations

import argparse
import sys

from tpnet_gpu.cli import bench, calibrate, dataset, demo, export, flow, inspect, process, ray, render, train

SUBCOMMANDS = (demo, process, render, inspect, dataset, train, bench, calibrate, flow, export)  # --help order


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tpnet", description=__doc__.split("\n\n")[0])
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what the library does: -v INFO, -vv DEBUG (before the subcommand; stderr)")
    sub = parser.add_subparsers(dest="command", required=True)
    made = {module: module.add_parser(sub) for module in SUBCOMMANDS}
    ray.add_options(made[process], made[dataset])
    return parser


def main(argv: list[str] | None = None) -> int:
    from tpnet_gpu.runtime.progress import verbosity  # noqa: PLC0415

    args = build_parser().parse_args(argv)
    try:
        with verbosity(args.verbose):
            return args.func(args)
    # the library refuses bad input with ValueError (RawFormatError is one) and files with OSError; a TypeError
    # here would be a bug of ours (the CLI builds every value it passes), so it keeps its traceback (issue 16)
    except (ValueError, OSError) as exc:
        print(f"tpnet {args.command}: error: {exc}", file=sys.stderr)
        return 2
