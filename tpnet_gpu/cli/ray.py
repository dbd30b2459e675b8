"""``--ray`` on ``tpnet process`` and ``tpnet dataset``: many scene folders, or a data set's scenes, spread over Ray
workers on this machine or a cluster (``tpnet_gpu.training.ray_jobs``, docs/scaling.md; needs the ``ray`` extra)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

RAY_HELP = ("spread the work over Ray workers (pip install 'tpnet-gpu[ray]'): a local Ray unless --address; "
            "finished outputs are kept and skipped (the run resumes)")


def add_options(process: argparse.ArgumentParser, dataset: argparse.ArgumentParser) -> None:
    """``--ray``, ``--address``, ``--workers`` on the ``process`` and ``dataset`` subcommands."""
    for parser, what in ((process, "with --ray: INPUTS are scene folders, each written to OUT/<folder name>"),
                         (dataset, "the missing scene chunks")):
        group = parser.add_argument_group("Ray", f"{RAY_HELP}; {what}")
        group.add_argument("--ray", action="store_true", help="run on Ray workers")
        group.add_argument("--address", default=None, metavar="HOST:PORT",
                           help="a running Ray cluster (`ray start --head` there; default: start Ray here)")
        group.add_argument("--workers", type=int, default=None, metavar="N",
                           help="Ray workers, one frame at a time each (default: one per CPU here, or per GPU / "
                                "CPU of the cluster)")


def options(args: argparse.Namespace):
    """The run's ``RayOptions``, or None without ``--ray`` (``--address``/``--workers`` then are an error)."""
    from tpnet_gpu.training.ray_jobs import RayOptions, import_ray  # noqa: PLC0415

    if not args.ray:
        for name in ("address", "workers"):
            if getattr(args, name) is not None:
                raise ValueError(f"--{name}: expected only with --ray, got {getattr(args, name)}")
        return None
    chosen = RayOptions(address=args.address, workers=args.workers)
    try:
        import_ray()  # a missing extra is said before any work, in one line
    except ModuleNotFoundError as exc:
        raise ValueError(str(exc)) from exc
    return chosen


def _plan(args: argparse.Namespace) -> tuple[list[dict], list[str]]:
    """Scenes still to do (``folder``, ``out``) and the names of those done, after checking the inputs."""
    from tpnet_gpu.outputs import check  # noqa: PLC0415

    folders = [Path(p) for p in args.inputs]
    for folder in folders:
        if not folder.is_dir():
            raise ValueError(f"inputs: expected scene folders with --ray, got {folder}, which is not a folder")
    names = [f.name for f in folders]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"inputs: expected scene folders of different names (each is written to OUT/NAME), got "
                         f"{', '.join(twice)} more than once")
    root = check(args.out, overwrite=True, inputs=folders)  # apart from every input; its folders are the outputs
    todo, done = [], []
    for folder in folders:
        out = root / folder.name
        if out.is_dir() and any(out.iterdir()) and not args.overwrite:
            done.append(folder.name)  # written whole or not at all (outputs.py): present means finished
        else:
            todo.append({"folder": str(folder.resolve()), "out": str(out)})
    return todo, done


def process_scenes(args: argparse.Namespace) -> int:
    """``tpnet process --ray DIR...``: each scene folder through ``tpnet process`` on a Ray worker."""
    from tpnet_gpu.training.ray_jobs import SceneWorker, run_pool  # noqa: PLC0415

    ray_options = options(args)
    if ray_options is None:
        raise ValueError("--ray: expected with --address or --workers")  # options() names the option it saw
    todo, done = _plan(args)
    start = time.perf_counter()
    passed = {**vars(args), "address": None, "workers": None}  # each worker runs the serial command
    rows = run_pool(todo, SceneWorker, {"options": passed}, ray_options, desc="scenes")
    failed = [r for r in rows if r["error"]]
    print(f"on Ray: {len(rows) - len(failed)} scene folders processed, {len(done)} done before (skipped), "
          f"{len(failed)} failed, in {time.perf_counter() - start:.1f} s -> {Path(args.out).resolve()}")
    for row in failed:
        print(f"tpnet process: error: {row['scene']}: {row['error']}", file=sys.stderr)
    return 1 if failed else 0
