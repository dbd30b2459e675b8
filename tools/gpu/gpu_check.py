"""The prepared GPU check of tpnet-gpu: one run on a lent CUDA machine, everything written under --out as JSON + text.

    python tools/gpu/gpu_check.py --out DIR [--budget-s 480] [--steps a,b,...]     # on the GPU machine (gpu_check.sh)
    python tools/gpu/gpu_check.py --out DIR --dry-run                             # here: the CPU, tiny sizes

Runner (this file) and steps (gpu_steps.py). Steps, in this order (the most telling first; each in its own try, time-boxed, skipped once the budget is spent;
the JSON is rewritten after every step, so a killed run still leaves what it did):

* ``env``: device, driver, versions.
* ``compile``: every Warp kernel module the processor loads (``warp_backend.KERNEL_MODULES``), each built in its
  own process at the launch block size, in parallel, into the shared Warp kernel cache; then loaded here from it.
* ``tp``: ``TileProcessor.process`` (load + convert + correlate + texture) and ``measure`` (one pass: centres +
  convert + correlate) at 640x480 and 2592x1936, graph capture off and on: build, first call (compile / record),
  median of --repeat (10) after that warm-up, peak device memory.
* ``pipeline_640x480``: ``Pipeline.process`` on the rendered demo scene: median frame of --repeat after a warm-up
  frame, then per stage (bench/throughput/throughput_pipeline.py's stage clock: engine search, engine refine, network,
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
import signal
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # gpu_steps.py beside this file, however it is loaded
import gpu_steps as gs  # noqa: E402
from gpu_steps import log  # noqa: E402

STEPS = ("env", "compile", "tp", "pipeline_640x480", "determinism", "tests", "pipeline_2592x1936", "memcheck",
         "racecheck")
BOXES = {"env": 30, "compile": 240, "tp": 120, "pipeline_640x480": 90, "determinism": 60, "tests": 150,
         "pipeline_2592x1936": 150, "memcheck": 90, "racecheck": 90}  # seconds each step may take at most
MIN_BOX = 10  # a step with less left than this is skipped


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
        gs.sanitizer_payload(args.device)
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
        "env": lambda box: gs.step_env(args),
        "compile": lambda box: gs.step_compile(args, box),
        "tp": lambda box: gs.step_tp(args),
        "pipeline_640x480": lambda box: gs.step_pipeline(args, *args.sizes[0], "demo"),
        "determinism": lambda box: gs.step_determinism(args),
        "tests": lambda box: gs.step_tests(args, box),
        "pipeline_2592x1936": lambda box: gs.step_pipeline(args, full_w, full_h, "random"),
        "memcheck": lambda box: gs.step_sanitizer(args, "memcheck", box),
        "racecheck": lambda box: gs.step_sanitizer(args, "racecheck", box),
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
