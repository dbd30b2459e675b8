"""Ray benchmark: many small scene folders through ``tpnet process``, serially and on Ray (docs/scaling.md).

    tpnet bench ray [--scenes 6] [--size 160x120] [--workers 1 2] [--repeat 1] [--json out/bench_ray.json]
    python -m tpnet_gpu.bench.throughput.bench_ray [same options]

``--scenes`` random scenes of ``--size`` are rendered once (supersample 1, ``tpnet render --scene random``). Each
row is one fresh Python process, timed from its start to its exit (imports, Ray's start and stop, every scene):

* serial, a process per scene: ``tpnet process SCENE`` once per scene (what one runs without Ray);
* serial, one process: the scenes one after another in one process, pipelines reused (``ray_jobs.process_scene``
  under ``ray_jobs.reused_pipelines``, the work a Ray worker does) - the peer the speed-ups are against;
* Ray, N workers: ``tpnet process --ray --workers N SCENE...`` (a local Ray of N CPUs);
* Ray start and stop: ``ray_jobs.session`` with no work, the fixed cost of a local Ray.

Every output is compared with the first row's (the same files, byte for byte). Medians of ``--repeat`` runs.
Prints a table and writes the numbers with machine information to JSON. Progress goes to stderr. Needs the
``ray`` extra.
"""

from __future__ import annotations

import contextlib
import filecmp
import os
import sys
import tempfile
from pathlib import Path

from tpnet_gpu.bench import common
from tpnet_gpu.bench.throughput.bench_startup import timed_child
from tpnet_gpu.bench.common import summary

log = common.logger("bench_ray")

SERIAL = """
import sys
from tpnet_gpu.cli import build_parser
from tpnet_gpu.training.ray_jobs import process_scene, reused_pipelines
out, scenes = sys.argv[1], sys.argv[2:]
with reused_pipelines():
    for scene in scenes:
        args = build_parser().parse_args(["process", scene, "--out", out + "/" + scene.rsplit("/", 1)[1],
                                          "--device", "cpu"])
        row = process_scene(scene, args.out, vars(args))
        assert not row["error"], row
"""
START_STOP = """
import sys
from tpnet_gpu.training.ray_jobs import RayOptions, session
with session(RayOptions(workers=int(sys.argv[1]))):
    pass
"""


def _same_outputs(first: Path, second: Path) -> bool:
    """Whether two output roots hold the same scene folders with byte-identical files."""
    names = sorted(p.name for p in first.iterdir())
    if names != sorted(p.name for p in second.iterdir()):
        return False
    for name in names:
        files = sorted(p.name for p in (first / name).iterdir())
        match, mismatch, errors = filecmp.cmpfiles(first / name, second / name, files, shallow=False)
        if mismatch or errors or files != sorted(p.name for p in (second / name).iterdir()):
            return False
    return True


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--scenes", type=int, default=6, help="scene folders (default 6)")
    parser.add_argument("--size", default="160x120", help="frame size WIDTHxHEIGHT (default 160x120)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="Ray pool sizes (default 1 2)")
    parser.add_argument("--repeat", type=int, default=1, help="runs per row (default 1)")
    parser.add_argument("--json", default="out/bench_ray.json", help="report file")
    args = parser.parse_args(argv)
    if args.scenes < 1 or args.repeat < 1 or min(args.workers) < 1:
        parser.error("--scenes, --repeat, --workers: expected at least 1")
    try:
        ((width, height),) = common.parse_sizes(args.size, "--size")
    except ValueError as error:
        parser.error(str(error))
    from tpnet_gpu import cli  # noqa: PLC0415
    from tpnet_gpu.training import ray_jobs

    try:
        ray_jobs.import_ray()
    except ModuleNotFoundError as exc:
        raise SystemExit(str(exc)) from None

    report = {"bench": "ray", "scenes": args.scenes, "width": width, "height": height, "rows": [],
              "machine": common.machine_info(load_average=os.getloadavg())}
    cpu = [sys.executable, "-m", "tpnet_gpu.cli", "process", "--device", "cpu"]
    with tempfile.TemporaryDirectory(prefix="tpnet-ray-") as tmp:
        tmp = Path(tmp)
        scenes = [str(tmp / "scenes" / f"s{i:03d}") for i in range(args.scenes)]
        for i, scene in enumerate(scenes):
            with contextlib.redirect_stdout(sys.stderr):  # its one-line summary is progress, not the table
                cli.main(["render", scene, "--scene", "random", "--seed", str(i), "--width", str(width),
                          "--height", str(height), "--supersample", "1"])
        rows = {"serial, a process per scene": lambda out: [cpu + [s, "--out", f"{out}/{Path(s).name}"]
                                                            for s in scenes],
                "serial, one process": lambda out: [[sys.executable, "-c", SERIAL, str(out), *scenes]]}
        for n in args.workers:
            rows[f"Ray, {n} worker{'s' if n > 1 else ''}"] = (
                lambda out, n=n: [cpu + ["--ray", "--workers", str(n), *scenes, "--out", str(out)]])
        first = None
        for name, commands in rows.items():
            runs = []
            for r in range(args.repeat):
                out = tmp / f"out-{len(report['rows'])}-{r}"
                runs.append(sum(timed_child(c, os.environ.copy())[0] for c in commands(out)))
                first = first or out
                if not _same_outputs(first, out):
                    raise SystemExit(f"{name}: outputs differ from the first row's")
            report["rows"].append({"mode": name, "wall_s": summary(runs)})
            log(f"{name}: median {report['rows'][-1]['wall_s']['median']:.1f} s")
        start_stop = [timed_child([sys.executable, "-c", START_STOP, str(max(args.workers))], os.environ.copy())[0]
                      for _ in range(args.repeat)]
        report["ray_start_stop_s"] = summary(start_stop)

    peer = next(r for r in report["rows"] if r["mode"] == "serial, one process")["wall_s"]["median"]
    header = ("mode", "wall s", "s / scene", "speed-up vs serial one process")
    table = []
    for row in report["rows"]:
        wall = row["wall_s"]["median"]
        row["speedup"] = peer / wall
        table.append((row["mode"], f"{wall:.1f}", f"{wall / args.scenes:.2f}", f"{peer / wall:.2f}x"))
    table.append((f"Ray start + stop, {max(args.workers)} CPUs, no work", f"{report['ray_start_stop_s']['median']:.1f}",
                  "", ""))
    report["table"] = common.format_table(header, table)
    print(f"{args.scenes} scenes of {width}x{height}, {os.cpu_count()} CPUs, load average "
          f"{report['machine']['load_average'][0]:.1f} at the start; outputs identical in every row")
    print("\n".join(report["table"]))
    log(f"wrote {common.save_json(report, args.json)}")
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
