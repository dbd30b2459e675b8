"""The issue-16 fuzz campaign: many drawn ``TileProcessor`` cases on both backends, then the ``Pipeline``, raw-reader
and CLI families, counted.

    tpnet bench fuzz [--examples 3000] [--seed 0] [--debug] [--pipeline 200] [--raw 2000] [--cli 200]
                     [--soak 1000] [--json ...]
    python -m tpnet_gpu.bench.fuzz.bench_fuzz [same options]

Draws the cases of ``bench/fuzz/fuzz_cases.py`` (the CI slice's, plus larger frames, so the count of tile tasks grows)
and checks each against the same oracles: nothing raises, ``valid`` as documented, correlations finite and zero
where the tile cannot be finite, Warp = Taichi on well-conditioned tiles. The campaign runs in a child process,
so a crash (a signal) is reported with the count reached, not lost. ``--debug`` runs the child with Taichi's debug
mode (``TPNET_TAICHI_DEBUG=1``) and Warp's debug builds (``TPNET_WARP_DEBUG=1``, warp_setup.DEBUG_ENV): bounds
checks on every array access, so an out-of-bounds access stops the child (counted as a crash) instead of reading
memory silently. After the tile cases the child draws ``--pipeline`` cases of bench/fuzz/fuzz_pipeline_cases.py,
``--raw`` files of bench/fuzz/fuzz_raw_cases.py (read in their own child processes, in batches of ``RAW_BATCH``) and
``--cli`` argument lists of bench/fuzz/fuzz_cli_cases.py, each against its module's oracles, with counts per family. Prints the counts (cases, tile tasks per
backend, valid tiles, failures by oracle) and saves JSON. Needs hypothesis (the ``test`` extra).

``--soak N`` also streams N frames of 64x48 through ``Pipeline.stream`` (shipped weights, Taichi), three good
frames in turn and a bad one (wrong shape, not an array, complex) every ``BAD_EVERY``: every bad frame must give
a ``FrameError``, every good one the same result bit for bit as that frame's first (nothing leaks between frames),
and the process RSS, sampled every ``BAD_EVERY`` frames, must stay flat.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from tpnet_gpu.bench import common

CAMPAIGN_SIZES = [(16, 16), (16, 24), (24, 16), (32, 48), (40, 40), (64, 96), (96, 128)]
PROGRESS_EVERY = 100  # cases between progress records (what a crash report can tell)
RAW_BATCH = 100  # raw files written and read per child process (it restarts after a crash)
FAMILIES = ("pipeline", "raw", "cli")
BAD_EVERY = 50  # soak: one bad frame in this many


def _rss_mib() -> float:
    """The process's resident set now (Linux /proc; NaN elsewhere)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return float("nan")
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def soak(frames_count: int, seed: int) -> dict:
    """Stream ``frames_count`` frames with a bad one every ``BAD_EVERY`` (module docstring); the counts."""
    import numpy as np  # noqa: PLC0415
    import torch  # noqa: PLC0415

    from tpnet_gpu.pipeline import FrameError, Pipeline  # noqa: PLC0415

    height, width = 48, 64
    rng = np.random.default_rng(seed)
    good = [rng.uniform(0, 3000, (4, height, width)).astype(np.float32) for _ in range(3)]
    bad = [good[0][:3], "not a frame", np.zeros((4, height, width), np.complex64)]
    plan = [("bad", bad[(i // BAD_EVERY) % 3]) if i % BAD_EVERY == BAD_EVERY - 1 else ("good", i % 3)
            for i in range(frames_count)]
    pipe = Pipeline(height, width, device="cpu", max_disparity=6.0, backend="taichi")
    first, counts, rss = {}, Counter(), []
    for i, result in enumerate(pipe.stream(frame if kind == "bad" else good[frame] for kind, frame in plan)):
        kind, frame = plan[i]
        if kind == "bad":
            counts["bad frames given a FrameError" if isinstance(result, FrameError) else "bad frames NOT refused"] += 1
        elif isinstance(result, FrameError):
            counts["good frames refused"] += 1
        else:
            got = (result.disparity.clone(), result.texture.clone())
            want = first.setdefault(frame, got)
            same = all(torch.equal(torch.nan_to_num(a, nan=-1.0), torch.nan_to_num(b, nan=-1.0))
                       for a, b in zip(got, want))
            counts["good frames equal to their first" if same else "good frames DIFFERENT"] += 1
        if i % BAD_EVERY == 0:
            rss.append(round(_rss_mib(), 1))
    return {"frames": frames_count, **counts, "rss_mib_every_50": rss,
            "rss_growth_mib": rss[-1] - rss[min(2, len(rss) - 1)] if rss else 0.0}


def _worker(examples: int, seed: int, progress: Path, families: dict) -> None:
    """Run the campaign in this process, writing the counts to ``progress`` every ``PROGRESS_EVERY`` cases."""
    from hypothesis import HealthCheck, Phase, given, settings  # noqa: PLC0415 - the test extra
    from hypothesis import seed as hypothesis_seed  # noqa: PLC0415

    from tpnet_gpu.bench.fuzz.fuzz_cases import cases, check  # noqa: PLC0415

    counts = {"cases": 0, "tile_tasks_per_backend": 0, "valid_tiles": 0, "failures": Counter(), "examples": [],
              "families": {}}

    def record(done: bool) -> None:
        progress.write_text(json.dumps({**counts, "failures": dict(counts["failures"]), "done": done}, default=str))

    @hypothesis_seed(seed)
    @settings(max_examples=examples, deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(cases(CAMPAIGN_SIZES))
    def campaign(case):
        outcome = check(case)
        counts["cases"] += 1
        counts["tile_tasks_per_backend"] += outcome["tiles"]
        counts["valid_tiles"] += outcome["valid"]
        counts["failures"].update(outcome["failures"])
        if outcome["failures"] and len(counts["examples"]) < 10:
            counts["examples"].append({"size": [case["height"], case["width"]], "cfa": case["cfa"],
                                       "magnitude": case["magnitude"], "failures": outcome["failures"]})
        if counts["cases"] % PROGRESS_EVERY == 0:
            record(False)

    campaign()
    record(False)
    for name, size in families.items():
        if size:
            counts["families"][name] = _family(name, size, seed, lambda: record(False))
            record(False)
    record(True)


def _family(name: str, size: int, seed: int, progress) -> dict:
    """Draw ``size`` cases of the Pipeline, raw-reader or CLI family (bench/fuzz_*_cases.py) and count them:
    cases, tile tasks (Pipeline: of the frames; raw: files read; CLI: exit statuses), measured tiles, failures."""
    import tempfile  # noqa: PLC0415

    from hypothesis import HealthCheck, Phase, given, settings  # noqa: PLC0415 - the test extra
    from hypothesis import seed as hypothesis_seed  # noqa: PLC0415
    from hypothesis import strategies as st  # noqa: PLC0415

    counts = {"cases": 0, "tile_tasks": 0, "measured_tiles": 0, "failures": Counter(), "examples": [],
              "statuses": Counter()}
    start = time.perf_counter()
    scratch = tempfile.TemporaryDirectory(prefix="tpnet-fuzz-")  # the CLI family's inputs and outputs
    folder = Path(scratch.name)

    def tally(failures, example):
        counts["failures"].update(failures)
        if failures and len(counts["examples"]) < 10:
            counts["examples"].append({"case": example, "failures": failures})

    if name == "pipeline":
        from tpnet_gpu.bench.fuzz.fuzz_pipeline_cases import cases, check  # noqa: PLC0415

        strategy, examples = cases(), size

        def one(case):
            outcome = check(case)
            counts["cases"] += 1
            counts["tile_tasks"] += outcome["tiles"]
            counts["measured_tiles"] += outcome["valid"]
            tally(outcome["failures"], {k: v for k, v in case.items() if k != "frames"})
    elif name == "raw":
        from tpnet_gpu.bench.fuzz.fuzz_raw_cases import raw_case, run  # noqa: PLC0415

        strategy, examples = st.lists(raw_case(), min_size=RAW_BATCH, max_size=RAW_BATCH), max(1, size // RAW_BATCH)

        def one(batch):
            for case, failure in zip(batch, run(batch)):
                counts["cases"] += 1
                tally([failure] if failure else [], case)
    else:
        from tpnet_gpu.bench.fuzz.fuzz_cli_cases import check, cli_case, fixture  # noqa: PLC0415

        paths = fixture(folder)
        strategy, examples = cli_case(), size

        def one(argv):
            outcome = check(argv, paths, folder)
            counts["cases"] += 1
            counts["statuses"][str(outcome["status"])] += 1
            tally(outcome["failures"], outcome["argv"])

    @hypothesis_seed(seed)
    @settings(max_examples=examples, deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def draw(case):
        one(case)
        if counts["cases"] % 10 == 0:
            progress()

    draw()
    scratch.cleanup()
    return {**counts, "failures": dict(counts["failures"]), "statuses": dict(counts["statuses"]),
            "seconds": time.perf_counter() - start}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(prog=common.prog(__name__), description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--examples", type=int, default=3000, help="drawn cases (each on both backends)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--debug", action="store_true",
                        help="Warp's debug mode and Taichi's debug mode (bounds checks on every array access)")
    parser.add_argument("--pipeline", type=int, default=200, help="Pipeline cases (fuzz_pipeline_cases; 0: none)")
    parser.add_argument("--raw", type=int, default=2000, help="raw files read (fuzz_raw_cases; 0: none)")
    parser.add_argument("--cli", type=int, default=200, help="tpnet argument lists (fuzz_cli_cases; 0: none)")
    parser.add_argument("--soak", type=int, default=0, help="also stream this many frames with bad ones (0: no)")
    parser.add_argument("--json", default="bench_fuzz.json", help="output JSON path ('' to skip)")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)  # the child's progress file
    args = parser.parse_args(argv)
    if args.examples < 1:
        parser.error(f"--examples: expected an int >= 1, got {args.examples}")
    for option in ("soak", *FAMILIES):
        if getattr(args, option) < 0:
            parser.error(f"--{option}: expected an int >= 0, got {getattr(args, option)}")
    families = {name: getattr(args, name) for name in FAMILIES}
    if args.worker:
        _worker(args.examples, args.seed, Path(args.worker), families)
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        progress = Path(tmp) / "progress.json"
        start = time.perf_counter()
        command = [sys.executable, "-m", "tpnet_gpu.bench.fuzz.bench_fuzz", "--examples", str(args.examples),
                   "--seed", str(args.seed), "--worker", str(progress),
                   *[f"--{name}={size}" for name, size in families.items()]]
        env = {**os.environ, **({"TPNET_TAICHI_DEBUG": "1", "TPNET_WARP_DEBUG": "1"} if args.debug else {})}
        child = subprocess.run(command, capture_output=True, text=True, env=env)
        seconds = time.perf_counter() - start
        counts = json.loads(progress.read_text()) if progress.exists() else {"cases": 0, "done": False}
    crashed = child.returncode != 0 or not counts.get("done")
    report = {"examples": args.examples, "seed": args.seed, "debug": args.debug, "seconds": seconds,
              "returncode": child.returncode,
              "crashed": crashed, "stderr_tail": child.stderr[-2000:] if crashed else "", **counts,
              "machine": common.machine_info()}
    failures = report.get("failures", {})
    rows = [["cases", report.get("cases", 0)], ["tile tasks per backend", report.get("tile_tasks_per_backend", 0)],
            ["valid tiles (Warp)", report.get("valid_tiles", 0)],
            ["crash", f"yes (exit {child.returncode}) after >= {report.get('cases', 0)} cases" if crashed else "no"],
            *[[f"failed: {name}", n] for name, n in sorted(failures.items())],
            ["failures in all", sum(failures.values())], ["seconds (all families)", f"{seconds:.0f}"]]
    for name, family in report.get("families", {}).items():
        extra = {"pipeline": [[f"{name}: tile tasks (measured)", f"{family['tile_tasks']} ({family['measured_tiles']})"]],
                 "cli": [[f"{name}: exit statuses", family["statuses"]]]}.get(name, [])
        rows += [[f"{name}: cases", family["cases"]], *extra, [f"{name}: failures", sum(family["failures"].values())],
                 *[[f"{name}: failed: {f}", n] for f, n in sorted(family["failures"].items())],
                 [f"{name}: seconds", f"{family['seconds']:.0f}"]]
    title = "fuzz campaign (both backends, CPU" + (", Warp and Taichi debug modes)" if args.debug else ")")
    if args.soak:
        report["soak"] = soak(args.soak, args.seed)
        rows += [[f"soak: {k}", v] for k, v in report["soak"].items() if k != "rss_mib_every_50"]
    table = common.format_table([title, "count"], [[str(c) for c in r] for r in rows])
    report["table"] = table
    print("\n".join(table))
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
