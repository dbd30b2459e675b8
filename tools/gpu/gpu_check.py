"""The prepared GPU check of tpnet-gpu: one run on a lent CUDA machine, everything written under --out as JSON + text.

    python tools/gpu/gpu_check.py --out DIR [--budget-s 480] [--steps a,b,...]     # on the GPU machine (gpu_check.sh)
    python tools/gpu/gpu_check.py --out DIR --dry-run                             # here: the CPU, tiny sizes

Steps, in this order (the most telling first; each in its own try, time-boxed, skipped once the budget is spent;
the JSON is rewritten after every step, so a killed run still leaves what it did):

* ``env``: device, driver, versions.
* ``tp``: ``TileProcessor.process`` (load + convert + correlate + texture) and ``measure`` (one pass: centres +
  convert + correlate) at 640x480 and 2592x1936, graph capture off and on: build, first call (compile / record),
  median of --repeat (10) after that warm-up, peak device memory.
* ``pipeline_640x480``: ``Pipeline.process`` on the rendered demo scene: median frame of --repeat after a warm-up
  frame, then per stage (bench/throughput_pipeline.py's stage clock: engine search, engine refine, network,
  texture, rest).
* ``determinism``: two runs bit-equal (float bits, NaN included): the processor's clt, corr, layers and texture
  with graphs off and on (and off vs on), and the pipeline's disparity, confidence and texture.
* ``tests``: the CUDA-parametrised tests (``pytest -k "cuda and not taichi and not cuda_compile"``: the sm_90
  compile tests need no GPU and run in the ordinary suite) in a subprocess, JUnit XML kept.
* ``pipeline_2592x1936``: as at 640x480, on random raw frames (rendering the demo scene at 5 MPix costs about a
  CPU-minute).
* ``memcheck``, ``racecheck``: ``compute-sanitizer --tool memcheck|racecheck`` on a 64x48 frame (a processor
  with graphs off and on, one pipeline frame: ``--sanitizer-payload``), when the tool is found.

Exit status: 0 when every step that ran passed, 1 when one failed, 2 without the device.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import shutil
import signal
import statistics
import subprocess
import sys
import time
import traceback
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the project root (tests/ lives there)
STEPS = ("env", "tp", "pipeline_640x480", "determinism", "tests", "pipeline_2592x1936", "memcheck", "racecheck")
BOXES = {"env": 30, "tp": 120, "pipeline_640x480": 90, "determinism": 60, "tests": 150, "pipeline_2592x1936": 150,
         "memcheck": 90, "racecheck": 90}  # seconds each step may take at most
MIN_BOX = 10  # a step with less left than this is skipped
TEST_SELECTION = "cuda and not taichi and not cuda_compile"


class StepTimeout(Exception):
    """A step ran past its time box."""


@contextlib.contextmanager
def time_box(seconds: int):
    """Raise ``StepTimeout`` in this (main) thread after ``seconds``."""
    def expire(signum, frame):
        raise StepTimeout(f"time box of {seconds} s spent")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(max(1, int(seconds)))
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


class Check:
    """Runs the steps within the budget, keeps their results and writes them out (JSON + text)."""

    def __init__(self, out: Path, budget_s: float, meta: dict):
        self.out, self.budget_s, self.start = out, budget_s, time.monotonic()
        self.report = {"meta": meta, "budget_s": budget_s, "steps": {}}
        out.mkdir(parents=True, exist_ok=True)

    def left(self) -> float:
        return self.budget_s - (time.monotonic() - self.start)

    def step(self, name: str, fn) -> dict:
        box = int(min(BOXES.get(name, 60), self.left()))
        if box < MIN_BOX:
            entry = {"ok": None, "skipped": f"budget spent ({self.left():.0f} s left)"}
        else:
            log(f"{name}: start (time box {box} s)")
            started = time.monotonic()
            try:
                with time_box(box):
                    entry = {"ok": True, **(fn(box) or {})}
            except Exception as exc:  # noqa: BLE001 - a check reports every failure and goes on
                entry = {"ok": False, "error": f"{type(exc).__name__}: {exc}"[:2000],
                         "trace": traceback.format_exc(limit=8)[-3000:]}
            entry["seconds"] = round(time.monotonic() - started, 2)
        self.report["steps"][name] = entry
        log(f"{name}: {verdict(entry)}")
        self.write()
        return entry

    def write(self) -> None:
        self.report["wall_s"] = round(time.monotonic() - self.start, 2)
        (self.out / "gpu_check.json").write_text(json.dumps(self.report, indent=1, default=str) + "\n")
        (self.out / "gpu_check.txt").write_text(summary_text(self.report))


def verdict(entry: dict) -> str:
    if entry.get("ok") is None:
        return f"SKIPPED ({entry.get('skipped')})"
    return "OK" if entry["ok"] else f"FAIL ({entry.get('error', '')[:200]})"


def summary_text(report: dict) -> str:
    lines = [f"tpnet-gpu GPU check: {report['meta'].get('device_name')} ({report['meta'].get('device')}), "
             f"wall {report.get('wall_s', 0):.0f} s of {report['budget_s']:.0f} s"]
    for name, entry in report["steps"].items():
        lines.append(f"{name:20s} {verdict(entry)} [{entry.get('seconds', 0):.1f} s]")
        for line in entry.get("summary", []):
            lines.append(f"    {line}")
    return "\n".join(lines) + "\n"


def log(message: str) -> None:
    print(f"[gpu_check] {message}", file=sys.stderr, flush=True)


# --- device helpers ----------------------------------------------------------------------------------------------
def make_sync(device: str):
    import torch
    import warp as wp

    def sync() -> None:
        wp.synchronize_device(device)
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    return sync


def timed(fn, sync) -> float:
    start = time.perf_counter()
    fn()
    sync()
    return 1e3 * (time.perf_counter() - start)


def median_ms(fn, sync, repeat: int) -> dict:
    runs = [timed(fn, sync) for _ in range(repeat)]
    return {"median": statistics.median(runs), "best": min(runs), "runs": [round(r, 4) for r in runs]}


def peak_memory(device: str, reset: bool = False) -> float | None:
    """Peak torch-allocated device memory (GB) since the last reset; None on the CPU (Warp's own pool is apart)."""
    import torch

    if not device.startswith("cuda"):
        return None
    if reset:
        torch.cuda.reset_peak_memory_stats()
        return None
    return torch.cuda.max_memory_allocated() / 1e9


def random_frames(width: int, height: int, device: str, seed: int = 0):
    import numpy as np
    import torch

    rng = np.random.default_rng(seed)
    return torch.from_numpy(rng.integers(0, 4096, (4, height, width)).astype(np.float32)).to(device)


def bits(t):
    """A float tensor's bits (int32 view, on the host): equal bits = equal values, NaNs included."""
    import torch

    return t.detach().contiguous().view(torch.int32).cpu()


# --- steps -------------------------------------------------------------------------------------------------------
def step_env(args) -> dict:
    import torch
    import warp as wp

    from tpnet_gpu.warp_setup import init_warp

    init_warp()
    smi = shutil.which("nvidia-smi")
    gpu = subprocess.run([smi, "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
                         capture_output=True, text=True, timeout=20).stdout.strip() if smi else None
    runtime = wp._src.context.runtime if hasattr(wp, "_src") else None
    return {"python": platform.python_version(), "torch": torch.__version__, "torch_cuda": torch.version.cuda,
            "torch_cuda_available": torch.cuda.is_available(), "warp": wp.__version__,
            "warp_cuda_devices": [str(d) for d in wp.get_cuda_devices()], "nvidia_smi": gpu,
            "warp_driver": getattr(runtime, "driver_version", None),
            "warp_toolkit": getattr(runtime, "toolkit_version", None),
            "summary": [f"{gpu or 'no nvidia-smi'}; torch {torch.__version__} (cuda {torch.version.cuda}); "
                        f"warp {wp.__version__}"]}


def step_tp(args) -> dict:
    import torch

    from tpnet_gpu.processor import TileProcessor

    sync, out, lines = make_sync(args.device), {}, []
    for width, height in args.sizes:
        frames = random_frames(width, height, args.device)
        for graph in (False, True):
            key = f"{width}x{height}_graph_{'on' if graph else 'off'}"
            peak_memory(args.device, reset=True)
            start = time.perf_counter()
            tp = TileProcessor(height, width, textures=True, graph=graph, device=args.device, backend="warp")
            build_ms = 1e3 * (time.perf_counter() - start)
            with torch.inference_mode():
                first_ms = timed(lambda: tp.process(frames, 2.5), sync)
                process = median_ms(lambda: tp.process(frames, 2.5), sync, args.repeat)
                tp.measure(2.5)  # records the measure graph
                sync()
                measure = median_ms(lambda: tp.measure(2.5), sync, args.repeat)
            out[key] = {"build_ms": build_ms, "first_process_ms": first_ms, "process_ms": process,
                        "measure_ms": measure, "peak_gb": peak_memory(args.device), "tiles": tp.tiles}
            lines.append(f"{key}: process {process['median']:.3f} ms, measure {measure['median']:.3f} ms "
                         f"(first call {first_ms:.0f} ms, build {build_ms:.0f} ms)")
            del tp
        del frames
    return {"runs": out, "what": "process = load + convert + correlate + texture; measure = centres + convert + "
                                 f"correlate; median of {args.repeat} after the first call", "summary": lines}


def step_pipeline(args, width: int, height: int, scene: str) -> dict:
    import torch

    from tpnet_gpu.bench.throughput_pipeline import STAGES, StageClock, scene_frames
    from tpnet_gpu.pipeline import Pipeline

    sync = make_sync(args.device)
    frames = torch.from_numpy(scene_frames(width, height, scene, 0)).to(args.device)
    peak_memory(args.device, reset=True)
    start = time.perf_counter()
    pipe = Pipeline(height, width, device=args.device, backend="warp")
    build_ms = 1e3 * (time.perf_counter() - start)
    with torch.inference_mode():
        first_ms = timed(lambda: pipe.process(frames), sync)
        frame = median_ms(lambda: pipe.process(frames), sync, args.repeat)
        clock = StageClock(pipe, sync)
        with clock.hooked():
            staged = [clock.frame(frames) for _ in range(args.repeat)]
        passes = float(pipe.process(frames).tile_passes)
    stages = {s: statistics.median(f[s] for f in staged) for s in STAGES}
    return {"size": f"{width}x{height}", "scene": scene, "build_ms": build_ms, "first_frame_ms": first_ms, "frame_ms": frame, "stages_ms": stages,
            "tile_passes": passes, "peak_gb": peak_memory(args.device), "graph": pipe.engine.tp.graph,
            "summary": [f"frame {frame['median']:.2f} ms ({1e3 / frame['median']:.1f} fps; first {first_ms:.0f} ms), "
                        + ", ".join(f"{s} {v:.2f}" for s, v in stages.items()) + f" ms; {passes:.2f} tile passes"]}


def step_determinism(args) -> dict:
    import torch

    from tpnet_gpu.bench.throughput_pipeline import scene_frames
    from tpnet_gpu.pipeline import Pipeline
    from tpnet_gpu.processor import TileProcessor

    width, height = args.sizes[0]
    frames = random_frames(width, height, args.device, seed=1)
    target = torch.rand((height // 8, width // 8), device=args.device) * 6.0 - 1.0
    names = ("clt", "corr", "layers", "texture")
    runs = {}
    with torch.inference_mode():
        for graph in (False, True):
            tp = TileProcessor(height, width, textures=True, graph=graph, device=args.device, backend="warp")
            runs[graph] = [{n: bits(getattr(tp.process(frames, target), n)) for n in names} for _ in range(2)]
            del tp
        pipe = Pipeline(height, width, device=args.device, backend="warp")
        scene = torch.from_numpy(scene_frames(width, height, "demo", 0)).to(args.device)
        pipeline = []
        for _ in range(2):
            r = pipe.process(scene)
            pipeline.append({n: bits(getattr(r, n)) for n in ("disparity", "confidence", "texture")})
    same = {f"graph_{'on' if g else 'off'}_run_to_run": {n: bool(torch.equal(a[n], b[n])) for n in names}
            for g, (a, b) in runs.items()}
    same["graph_off_vs_on"] = {n: bool(torch.equal(runs[False][0][n], runs[True][0][n])) for n in names}
    same["pipeline_run_to_run"] = {n: bool(torch.equal(pipeline[0][n], pipeline[1][n])) for n in pipeline[0]}
    bad = [f"{k}.{n}" for k, v in same.items() if k != "graph_off_vs_on" for n, ok in v.items() if not ok]
    if bad:
        raise AssertionError(f"not bit-equal between two runs: {', '.join(bad)} ({json.dumps(same)})")
    return {"bit_equal": same, "size": f"{width}x{height}",
            "summary": ["run to run bit-equal: processor (graph off, on) and pipeline; graph off vs on: "
                        + ", ".join(f"{n} {'=' if ok else '!='}" for n, ok in same["graph_off_vs_on"].items())]}


def junit_counts(path: Path) -> dict:
    root = ET.parse(path).getroot()
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    tests, failures, errors, skipped = (int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
    failed = [f"{case.get('classname')}::{case.get('name')}: {(bad.get('message') or '').splitlines()[0][:200]}"
              for case in root.iter("testcase") for bad in (*case.findall("failure"), *case.findall("error"))]
    return {"tests": tests, "passed": tests - failures - errors - skipped, "failed": failures, "errors": errors,
            "skipped": skipped, "failures": failed[:20]}


def step_tests(args, box: int) -> dict:
    xml = args.out / "tests_cuda.xml"
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", TEST_SELECTION,
           "--continue-on-collection-errors", "--junitxml", str(xml), str(ROOT / "tests")]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=max(5, box - 5))
    (args.out / "tests_cuda.txt").write_text(done.stdout[-200_000:] + done.stderr[-50_000:])
    counts = junit_counts(xml)
    if done.returncode not in (0, 5) or counts["failed"] or counts["errors"]:  # 5: nothing collected
        raise AssertionError(f"pytest exit status {done.returncode}: {json.dumps(counts)[:1500]}")
    return {**counts, "selection": TEST_SELECTION,
            "summary": [f"{counts['passed']} passed, {counts['skipped']} skipped of {counts['tests']} "
                        f"(-k '{TEST_SELECTION}')"]}


def find_sanitizer() -> str | None:
    found = shutil.which("compute-sanitizer")
    if found:
        return found
    for root in sorted(Path("/usr/local").glob("cuda*"), reverse=True):
        if (root / "bin" / "compute-sanitizer").exists():
            return str(root / "bin" / "compute-sanitizer")
    return None


def step_sanitizer(args, tool: str, box: int) -> dict:
    tool_path = find_sanitizer()
    if tool_path is None:
        return {"ok": None, "skipped": "compute-sanitizer not found (PATH, /usr/local/cuda*/bin)"}
    report = args.out / f"{tool}.txt"
    cmd = [tool_path, "--tool", tool, "--error-exitcode", "3", "--log-file", str(report), sys.executable,
           str(Path(__file__).resolve()), "--sanitizer-payload", "--device", args.device]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=max(5, box - 5))
    text = report.read_text() if report.exists() else ""
    tail = [line for line in text.splitlines() if "ERROR SUMMARY" in line or "RACECHECK SUMMARY" in line]
    if done.returncode != 0:
        raise AssertionError(f"{tool}: exit status {done.returncode}; {' '.join(tail)}; {done.stderr[-800:]}")
    return {"summary": tail or [f"{tool}: clean"], "payload_stdout": done.stdout[-1000:]}


def sanitizer_payload(device: str) -> None:
    """What the sanitizer watches: a 64x48 processor with graphs off and on, and one pipeline frame."""
    import torch

    from tpnet_gpu.pipeline import Pipeline
    from tpnet_gpu.processor import TileProcessor

    frames = random_frames(64, 48, device)
    with torch.inference_mode():
        for graph in (False, True):
            tp = TileProcessor(48, 64, textures=True, graph=graph, device=device, backend="warp")
            for _ in range(2):
                tp.process(frames, 1.5)
        Pipeline(48, 64, device=device, backend="warp").process(frames)
    make_sync(device)()
    print("sanitizer payload done")


# --- main --------------------------------------------------------------------------------------------------------
def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "out/gpu_check")))
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--budget-s", type=float, default=480.0, help="wall seconds for every step (default 480)")
    parser.add_argument("--repeat", type=int, default=10, help="timed calls after the warm-up (default 10)")
    parser.add_argument("--steps", default=",".join(STEPS), help=f"comma-separated subset of {','.join(STEPS)}")
    parser.add_argument("--dry-run", action="store_true",
                        help="the CPU at 64x48, 2 repeats, the 5 MPix pipeline at 64x48 too: every step end to end")
    parser.add_argument("--sanitizer-payload", action="store_true", help=argparse.SUPPRESS)  # the sanitizer's child
    args = parser.parse_args(argv)
    args.steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    unknown = sorted(set(args.steps) - set(STEPS))
    if unknown:
        parser.error(f"--steps: expected names from {', '.join(STEPS)}, got {', '.join(unknown)}")
    if args.repeat < 1:
        parser.error("--repeat: expected at least 1")
    args.sizes, args.full = [(640, 480), (2592, 1936)], (2592, 1936)
    if args.dry_run:
        args.device, args.repeat, args.sizes, args.full = "cpu", min(args.repeat, 2), [(64, 48)], (64, 48)
    return args


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    os.environ.setdefault("WARP_CACHE_PATH", "/tmp/warp-cache")
    os.environ.setdefault("TPNET_CACHE_DIR", "/tmp/tpnet-cache")
    if args.sanitizer_payload:
        sanitizer_payload(args.device)
        return 0
    import torch

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        check = Check(args.out, args.budget_s, {"device": args.device, "device_name": "none"})
        check.report["steps"]["env"] = {"ok": False, "error": "torch sees no CUDA device"}
        check.write()
        log("no CUDA device: stopping")
        return 2
    from tpnet_gpu.bench.common import cpu_model

    name = torch.cuda.get_device_name() if args.device.startswith("cuda") else f"CPU ({cpu_model()})"
    check = Check(args.out, args.budget_s, {"device": args.device, "device_name": name, "repeat": args.repeat,
                                            "dry_run": args.dry_run, "argv": sys.argv[1:] if argv is None else argv})
    full_w, full_h = args.full
    steps = {
        "env": lambda box: step_env(args),
        "tp": lambda box: step_tp(args),
        "pipeline_640x480": lambda box: step_pipeline(args, *args.sizes[0], "demo"),
        "determinism": lambda box: step_determinism(args),
        "tests": lambda box: step_tests(args, box),
        "pipeline_2592x1936": lambda box: step_pipeline(args, full_w, full_h, "random"),
        "memcheck": lambda box: step_sanitizer(args, "memcheck", box),
        "racecheck": lambda box: step_sanitizer(args, "racecheck", box),
    }
    for name in args.steps:
        entry = check.step(name, steps[name])
        if name == "env" and entry.get("ok") is False:
            break  # nothing else can run
    check.write()
    print(summary_text(check.report), end="")
    return 1 if any(e.get("ok") is False for e in check.report["steps"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
