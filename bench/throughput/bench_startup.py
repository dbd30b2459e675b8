"""Start-up benchmark: a one-shot ``tpnet process`` of a small rendered scene, each in a fresh process.

    tpnet bench startup [--sizes 128x96 640x480] [--backends default taichi warp] [--repeat 3] [--cache DIR]
                        [--pair] [--figures] [--json out/bench_startup.json]
    python -m tpnet_gpu.bench.throughput.bench_startup [same options]

Per frame size a demo scene is rendered once (supersample 1, ``tpnet render``) - or with ``--pair`` a mono stereo
pair as PNG images (``rendered_pairs``' real-like case, processed as ``tpnet process LEFT RIGHT --max-disparity
64``, at most a quarter of the width: the cross-check and the per-pixel step). Per size and backend, ``tpnet
process INPUTS --device cpu [--backend B]`` (backend "default": no ``--backend``, the command's own choice) runs
in a fresh Python process: first with an empty kernel cache (the cold row: Taichi's offline cache and Warp's
kernel cache both in a new temporary folder, ``TPNET_CACHE_DIR`` and ``WARP_CACHE_PATH``), then ``--repeat``
times with that cache (the warm row: median and best). With ``--cache DIR`` the processes share DIR instead (no
cold row). Each row gives medians of the process's wall time, its CPU time (user + system, every thread: less
sensitive than the wall time to other load on the machine), the seconds the command itself reports (pipeline
construction and the first frame: what start-up costs beyond the imports) and the kernels each run added to the
cache (Taichi ``.tic`` files, Warp module folders: 0 when the cache was hit). The runs pass ``--no-figures``
(start-up, not plots); ``--figures`` adds a warm row of the command as a user types it, its labelled figures
written too ("warm, figures"). The import floor is ``python -c
"import tpnet_gpu.pipeline"`` (Python, NumPy, torch, Warp and the pipeline's modules); the torch floor ``python -c
"import torch"``, the part no one-shot that runs the engine (torch throughout) can go below.

Prints a table and writes the numbers with machine information to JSON. Progress goes to stderr.
"""

from __future__ import annotations

import contextlib
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tpnet_gpu.bench import common
from tpnet_gpu.bench.common import summary

log = common.logger("bench_startup")

BACKENDS = ("default", "taichi", "warp")  # default: no --backend (the command's own choice for the frame size)
IMPORT_FLOOR = "import tpnet_gpu.pipeline"
TORCH_FLOOR = "import torch"
_REPORTED = re.compile(r" in ([0-9.]+) s -> ")  # `tpnet process`: "processed ... frame ... in 1.2 s -> OUT: ..."


def cache_env(root: Path) -> dict:
    """The environment of a child that keeps both kernel caches under ``root``."""
    return {**os.environ, "TPNET_CACHE_DIR": str(root), "WARP_CACHE_PATH": str(root / "warp")}


def cache_entries(root: Path) -> int:
    """Compiled kernels in the caches under ``root``: Taichi ``.tic`` files plus Warp module folders."""
    taichi = len(list((root / "taichi").glob("*.tic")))
    warp = sum(1 for p in (root / "warp").glob("*/wp_*") if p.is_dir())
    return taichi + warp


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed_child(command: list[str], env: dict) -> tuple[float, float, str]:
    """Wall seconds, CPU seconds (user + system, all threads) and stdout of ``command`` run to completion (a
    failure raises with its stderr's tail)."""
    cpu, start = _children_cpu(), time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    seconds, cpu = time.perf_counter() - start, _children_cpu() - cpu
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed ({done.returncode}): {done.stderr[-2000:]}")
    return seconds, cpu, done.stdout


def process_once(inputs: list, tmp: Path, backend: str, root: Path, figures: bool = False) -> dict:
    """One ``tpnet process`` in a fresh process over the caches under ``root``, into a new output folder under
    ``tmp`` (the command refuses one that holds files): wall and reported seconds, and the kernels it added to
    the caches. ``figures``: without ``--no-figures``."""
    before = cache_entries(root)
    out = Path(tempfile.mkdtemp(prefix="out-", dir=tmp))
    command = [sys.executable, "-m", "tpnet_gpu.cli", "process", *inputs, "--out", str(out), "--device", "cpu",
               *([] if figures else ["--no-figures"]), *([] if backend == "default" else ["--backend", backend])]
    wall, cpu, stdout = timed_child(command, cache_env(root))
    reported = _REPORTED.search(stdout)
    if reported is None:
        raise RuntimeError(f"tpnet process printed no time: {stdout!r}")
    if figures != ("disparity.png" in stdout):  # the row is what it says
        raise RuntimeError(f"tpnet process {'wrote no' if figures else 'wrote'} figures: {stdout!r}")
    return {"wall_s": wall, "cpu_s": cpu, "reported_s": float(reported.group(1)),
            "new_kernels": cache_entries(root) - before}


def _inputs(tmp: Path, width: int, height: int, pair: bool) -> list[str]:
    """The ``tpnet process`` inputs of one size, rendered into ``tmp``: a quad scene folder, or a pair's images and
    its range (``--pair``)."""
    if pair:
        from tpnet_gpu.bench.accuracy.rendered_pairs import MAX_DISPARITY, write_suite  # noqa: PLC0415

        (folder,) = write_suite(tmp / f"pair-{width}x{height}", cases=("real-like",), size=(width, height),
                                supersample=1)
        reach = min(MAX_DISPARITY, width // 4)  # a tiny smoke-test frame cannot hold the suite's 64 px
        return [str(folder / "left.png"), str(folder / "right.png"), "--max-disparity", f"{reach:g}"]
    from tpnet_gpu import cli  # noqa: PLC0415 - the renderer, in this process

    scene = tmp / f"scene-{width}x{height}"
    with contextlib.redirect_stdout(sys.stderr):  # its one-line summary is progress, not the table
        rendered = cli.main(["render", str(scene), "--width", str(width), "--height", str(height), "--supersample",
                             "1"])
    if rendered != 0:
        raise SystemExit(f"could not render a {width}x{height} scene")
    return [str(scene)]


def _row(runs: list[dict]) -> dict:
    return {**{key: summary([r[key] for r in runs]) for key in ("wall_s", "cpu_s", "reported_s")},
            "new_kernels": [r["new_kernels"] for r in runs]}


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--sizes", nargs="+", default=["128x96"], help="frame sizes WIDTHxHEIGHT")
    parser.add_argument("--backends", nargs="+", choices=BACKENDS, default=list(BACKENDS))
    parser.add_argument("--repeat", type=int, default=3, help="warm runs per size and backend (default 3)")
    parser.add_argument("--cache", default=None, metavar="DIR",
                        help="kernel cache root shared by every run (default: a new one per backend, cold first)")
    parser.add_argument("--pair", action="store_true", help="a rendered mono stereo pair of PNG images instead of a "
                        "quad scene folder")
    parser.add_argument("--figures", action="store_true", help="also a warm row with the command's figures (its "
                        "default output)")
    parser.add_argument("--json", default="out/bench_startup.json", help="report file")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat: expected at least 1")
    try:
        sizes = common.parse_sizes(",".join(args.sizes), "--sizes")
    except ValueError as error:
        parser.error(str(error))

    report = {"bench": "startup", "inputs": "mono pair" if args.pair else "quad scene", "sizes": [],
              "machine": common.machine_info(), "cache": args.cache}
    with tempfile.TemporaryDirectory(prefix="tpnet-startup-") as tmp:
        tmp = Path(tmp)
        for key, code in (("torch_floor", TORCH_FLOOR), ("import_floor", IMPORT_FLOOR)):
            floor = [timed_child([sys.executable, "-c", code], os.environ.copy()) for _ in range(args.repeat)]
            report[key] = {"wall_s": summary([f[0] for f in floor]), "cpu_s": summary([f[1] for f in floor])}
            log(f"{key.replace('_', ' ')} ({code}): median {report[key]['wall_s']['median']:.2f} s")
        for width, height in sizes:
            inputs = _inputs(tmp, width, height, args.pair)
            entry = {"width": width, "height": height, "backends": {}}
            for backend in args.backends:
                root = Path(args.cache) if args.cache else tmp / f"cache-{width}x{height}-{backend}"
                rows = {}
                if not args.cache:
                    rows["cold"] = _row([process_once(inputs, tmp, backend, root)])
                    log(f"{width}x{height} {backend} cold: {rows['cold']['wall_s']['median']:.2f} s")
                warm = [process_once(inputs, tmp, backend, root) for _ in range(args.repeat)]
                rows["warm"] = _row(warm)
                log(f"{width}x{height} {backend} warm: median {rows['warm']['wall_s']['median']:.2f} s")
                if args.figures:
                    rows["warm, figures"] = _row([process_once(inputs, tmp, backend, root, figures=True)
                                                  for _ in range(args.repeat)])
                    log(f"{width}x{height} {backend} warm, figures: median "
                        f"{rows['warm, figures']['wall_s']['median']:.2f} s")
                entry["backends"][backend] = rows
            report["sizes"].append(entry)

    header = ("frame / backend / cache", "wall s", "CPU s", "reported s", "kernels compiled")
    table = [(f"{key.replace('_', ' ')}: {code}", f"{report[key]['wall_s']['median']:.2f}",
              f"{report[key]['cpu_s']['median']:.2f}", "", "")
             for key, code in (("torch_floor", TORCH_FLOOR), ("import_floor", IMPORT_FLOOR))]
    for entry in report["sizes"]:
        for backend, rows in entry["backends"].items():
            for kind, row in rows.items():
                table.append((f"{entry['width']}x{entry['height']} {backend} {kind}",
                              *(f"{row[key]['median']:.2f}" for key in ("wall_s", "cpu_s", "reported_s")),
                              ",".join(map(str, row["new_kernels"]))))
    report["table"] = common.format_table(header, table)
    print("\n".join(report["table"]))
    log(f"wrote {common.save_json(report, args.json)}")
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
