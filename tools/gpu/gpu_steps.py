"""The steps of the prepared GPU check (gpu_check.py, which runs them in order, time-boxed; its docstring says
what each one does). Each ``step_*`` returns its JSON entry (a ``summary`` list of text lines among the numbers)
or raises; imports of the project and of torch happen inside, so the runner itself starts without them."""

from __future__ import annotations

import json
import platform
import shutil
import statistics
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the project root (tests/ lives there)
TEST_SELECTION = "cuda and not taichi and not cuda_compile"


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


def timed_runs(fn, sync, repeat: int) -> dict:
    """``repeat`` timed calls (ms): median, best, every run (bench.common.summary)."""
    from tpnet_gpu.bench.common import summary, timed_ms

    return summary([timed_ms(fn, sync) for _ in range(repeat)])


def memory(device: str, reset: bool = False) -> dict | None:
    """Device memory now, GB: torch's peak allocation since the last reset (Warp's own buffers are not in it) and
    the whole device's use (total - free: Warp's buffers and pools, torch's cache, the context). None on the CPU."""
    import torch

    if not device.startswith("cuda"):
        return None
    if reset:
        torch.cuda.reset_peak_memory_stats()
        return None
    free, total = torch.cuda.mem_get_info()
    return {"torch_peak_gb": torch.cuda.max_memory_allocated() / 1e9, "device_used_gb": (total - free) / 1e9}


def device_frames(width: int, height: int, device: str, seed: int = 0):
    """``(4, height, width)`` float32 random raw quad frames (bench.common.random_frames) on ``device``."""
    import numpy as np
    import torch

    from tpnet_gpu.bench.common import random_frames

    return torch.from_numpy(random_frames(np.random.default_rng(seed), height, width)).to(device)


def bits(t):
    """A float tensor's bits (int32 view, on the host): equal bits = equal values, NaNs included."""
    import torch

    return t.detach().contiguous().view(torch.int32).cpu()


# --- steps -------------------------------------------------------------------------------------------------------
def step_env(args) -> dict:
    import torch
    import warp as wp

    from tpnet_gpu.runtime.warp_setup import init_warp

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


COMPILE_ONE = """
import sys, time
import warp as wp
from tpnet_gpu.runtime.warp_setup import init_warp
from tpnet_gpu.layout import CPU_BLOCK_DIM, CUDA_BLOCK_DIM
from tpnet_gpu.processor import warp_backend
init_warp()
device = wp.get_device(sys.argv[1])
module = next(m for m in warp_backend.KERNEL_MODULES if m.__name__ == sys.argv[2])
start = time.perf_counter()
wp.load_module(module, device=device, block_dim=CUDA_BLOCK_DIM if device.is_cuda else CPU_BLOCK_DIM)
print(f"{time.perf_counter() - start:.2f}")
"""


def step_compile(args, box: int) -> dict:
    import warp as wp

    from tpnet_gpu.layout import CPU_BLOCK_DIM, CUDA_BLOCK_DIM
    from tpnet_gpu.processor import warp_backend

    names = [m.__name__ for m in warp_backend.KERNEL_MODULES]
    start = time.perf_counter()
    workers = {n: subprocess.Popen([sys.executable, "-c", COMPILE_ONE, args.device, n], cwd=ROOT, text=True,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE) for n in names}
    built, errors = {}, {}
    try:
        for name, worker in workers.items():
            out, err = worker.communicate(timeout=max(5.0, box - 5 - (time.perf_counter() - start)))
            if worker.returncode == 0:
                built[name] = float(out.strip().splitlines()[-1])
            else:
                errors[name] = err[-1500:]
    finally:
        for worker in workers.values():
            if worker.poll() is None:
                worker.kill()
    wall = time.perf_counter() - start
    device = wp.get_device(args.device)
    start = time.perf_counter()
    for module in warp_backend.KERNEL_MODULES:  # from the cache now
        wp.load_module(module, device=device, block_dim=CUDA_BLOCK_DIM if device.is_cuda else CPU_BLOCK_DIM)
    cached_s = time.perf_counter() - start
    if errors:
        raise RuntimeError(f"compile failed: {json.dumps(errors)[:1800]}")
    return {"compile_s": built, "parallel_wall_s": wall, "load_from_cache_s": cached_s,
            "summary": [f"{len(built)} modules in {wall:.1f} s wall (parallel), "
                        + ", ".join(f"{n.rpartition('.')[2]} {t:.1f} s" for n, t in built.items())
                        + f"; loaded from the cache in {cached_s:.2f} s"]}


def step_tp(args) -> dict:
    import torch

    from tpnet_gpu.processor import TileProcessor

    sync, out, lines = make_sync(args.device), {}, []
    for width, height in args.sizes:
        frames = device_frames(width, height, args.device)
        for graph in (False, True):
            key = f"{width}x{height}_graph_{'on' if graph else 'off'}"
            memory(args.device, reset=True)
            start = time.perf_counter()
            tp = TileProcessor(height, width, textures=True, clt=True, graph=graph, device=args.device, backend="warp")
            build_ms = 1e3 * (time.perf_counter() - start)
            with torch.inference_mode():
                first_ms = timed_runs(lambda: tp.process(frames, 2.5), sync, 1)["median"]
                process = timed_runs(lambda: tp.process(frames, 2.5), sync, args.repeat)
                timed_runs(lambda: tp.measure(2.5), sync, 1)  # records the measure graph
                measure = timed_runs(lambda: tp.measure(2.5), sync, args.repeat)
            out[key] = {"build_ms": build_ms, "first_process_ms": first_ms, "process_ms": process,
                        "measure_ms": measure, "memory": memory(args.device), "tiles": tp.tiles}
            lines.append(f"{key}: process {process['median']:.3f} ms, measure {measure['median']:.3f} ms "
                         f"(first call {first_ms:.0f} ms, build {build_ms:.0f} ms)")
            del tp
        del frames
    return {"runs": out, "what": "process = load + convert + correlate + texture; measure = centres + convert + "
                                 f"correlate; median of {args.repeat} after the first call", "summary": lines}


def step_pipeline(args, width: int, height: int, scene: str) -> dict:
    import torch

    from tpnet_gpu.bench.throughput.throughput_pipeline import STAGES, StageClock, scene_frames
    from tpnet_gpu.pipeline import Pipeline

    sync = make_sync(args.device)
    frames = torch.from_numpy(scene_frames(width, height, scene, 0)).to(args.device)
    memory(args.device, reset=True)
    start = time.perf_counter()
    pipe = Pipeline(height, width, device=args.device, backend="warp")
    build_ms = 1e3 * (time.perf_counter() - start)
    with torch.inference_mode():
        first_ms = timed_runs(lambda: pipe.process(frames), sync, 1)["median"]
        frame = timed_runs(lambda: pipe.process(frames), sync, args.repeat)
        clock = StageClock(pipe, sync)
        with clock.hooked():
            staged = [clock.frame(frames) for _ in range(args.repeat)]
        passes = float(clock.result.tile_passes)
    stages = {s: statistics.median(f[s] for f in staged) for s in STAGES}
    return {"size": f"{width}x{height}", "scene": scene, "build_ms": build_ms, "first_frame_ms": first_ms,
            "frame_ms": frame, "stages_ms": stages, "tile_passes": passes, "memory": memory(args.device),
            "graph": pipe.engine.tp.graph,
            "summary": [f"frame {frame['median']:.2f} ms ({1e3 / frame['median']:.1f} fps; first {first_ms:.0f} ms), "
                        + ", ".join(f"{s} {v:.2f}" for s, v in stages.items()) + f" ms; {passes:.2f} tile passes"]}


def step_determinism(args) -> dict:
    import torch

    from tpnet_gpu.bench.throughput.throughput_pipeline import scene_frames
    from tpnet_gpu.pipeline import Pipeline
    from tpnet_gpu.processor import TileProcessor

    width, height = args.sizes[0]
    frames = device_frames(width, height, args.device, seed=1)
    target = torch.rand((height // 8, width // 8), device=args.device) * 6.0 - 1.0
    names = ("clt", "corr", "layers", "texture")
    runs = {}
    with torch.inference_mode():
        for graph in (False, True):
            tp = TileProcessor(height, width, textures=True, clt=True, graph=graph, device=args.device, backend="warp")
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
    with open(args.out / "tests_cuda.txt", "w") as text:  # written as it goes: kept when the box runs out
        done = subprocess.run(cmd, cwd=ROOT, stdout=text, stderr=subprocess.STDOUT, timeout=max(5, box - 5))
    if not xml.exists():
        tail = (args.out / "tests_cuda.txt").read_text()[-1500:]
        raise AssertionError(f"pytest exit status {done.returncode}, no JUnit report: {tail}")
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
           str(Path(__file__).resolve().parent / "gpu_check.py"), "--sanitizer-payload", "--device", args.device]
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

    frames = device_frames(64, 48, device)
    with torch.inference_mode():
        for graph in (False, True):
            tp = TileProcessor(48, 64, textures=True, clt=True, graph=graph, device=device, backend="warp")
            for _ in range(2):
                tp.process(frames, 1.5)
        Pipeline(48, 64, device=device, backend="warp").process(frames)
    make_sync(device)()
    print("sanitizer payload done")
