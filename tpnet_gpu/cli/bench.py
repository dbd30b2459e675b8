"""``tpnet bench NAME [ARGS]``: one benchmark of ``tpnet_gpu.bench`` (a table printed, JSON saved)."""

from __future__ import annotations

import argparse

# name -> the module (under tpnet_gpu.bench, by group) whose main(args) runs it
GROUPS = {
    "accuracy": ("accuracy", "network", "network_limits", "network_context", "calibration", "flow", "two_surface",
                 "real", "rendered_pairs", "video"),
    "throughput": ("tp", "throughput", "startup", "ray"),
    "fuzz": ("fuzz",),
}
BENCHES = {name: f"{group}.bench_{name}" for group, names in GROUPS.items() for name in names}


def run(args: argparse.Namespace) -> int:
    import importlib  # noqa: PLC0415

    from tpnet_gpu.bench import common  # noqa: PLC0415

    # its --help, a bad option or a missing optional dependency (the ``bench`` extra) end with argparse's status
    # or a one-line message (common.run), not a traceback
    module = importlib.import_module(f"tpnet_gpu.bench.{BENCHES[args.name]}")
    return common.run(module.main, args.args)


def add_parser(sub) -> argparse.ArgumentParser:
    bench = sub.add_parser("bench", help="run a benchmark of tpnet_gpu.bench (table + JSON)",
                           description="Runs a benchmark of tpnet_gpu.bench (its module also runs as `python -m "
                                       "tpnet_gpu.bench.MODULE`) with the remaining arguments, e.g. `tpnet bench tp "
                                       "--height 480 --width 640`.")
    bench.add_argument("name", choices=list(BENCHES), help="which benchmark")
    bench.add_argument("args", nargs=argparse.REMAINDER,
                       help="arguments for the benchmark (see `tpnet bench NAME --help`)")
    bench.set_defaults(func=run)
    return bench
