"""Peak memory of ``Pipeline.process`` on one frame size, and what holds it.

    python -m tpnet_gpu.bench.throughput.frame_memory [--height 1936 --width 2592] [--frames demo|random] [--json out.json]

Each measurement runs in a fresh child process (``ru_maxrss`` is a process-lifetime peak): the frames are made
first (the demo scene rendered without supersampling, or ``common.random_frames``) and saved to a temporary
``.npy`` by another child, so rendering never counts. The child reports the peak RSS after ``import``, after
building the pipeline, and after each of ``--frames-run`` frames, the wall and CPU seconds of each frame (medians
printed; the first includes compile and cache warm-up), and the bytes of every device buffer the pipeline owns (tile-processor ``Buffers`` arrays by name, the engine's cost volumes, the network's parameters).
Runs over ~2 GB must be serialised on a shared machine (``flock /tmp/bigrun.lock python -m ...``).
"""

from __future__ import annotations

import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tpnet_gpu.bench import common

log = common.logger("frame_memory")
MIB = 2**20


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB


def _make_frames(kind: str, height: int, width: int, path: str) -> None:
    """Child: the frames ``(4, H, W)`` float32, black-subtracted, saved to ``path``."""
    if kind == "random":
        frames = common.random_frames(np.random.default_rng(0), height, width)
    else:
        from tpnet_gpu.camera import Rig  # noqa: PLC0415
        from tpnet_gpu.scenes import demo_scene, render  # noqa: PLC0415

        rig = Rig(width=width, height=height)
        rendered = render(demo_scene(rig, seed=0), rig, supersample=1, seed=0)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    np.save(path, frames)


def buffer_bytes(pipe) -> dict:
    """Bytes of every device array the pipeline owns, by owner and name (largest first)."""
    import warp as wp  # noqa: PLC0415

    out = {}
    processors = {"tp": pipe.engine.tp}
    if pipe.network_tp is not None and pipe.network_tp is not pipe.engine.tp:
        processors["network_tp"] = pipe.network_tp
    for label, tp in processors.items():
        for name, value in vars(tp._buffers).items():
            if isinstance(value, wp.array):
                out[f"{label}.{name}"] = value.capacity
    for name in ("volume", "sparse_volume"):
        out[f"engine.{name}"] = getattr(pipe.engine, name).values.nbytes
    if pipe.model is not None:
        out["model.parameters"] = sum(p.nbytes for p in pipe.model.parameters())
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def _measure(path: str, frames_run: int, device: str) -> None:
    """Child: peak RSS (MiB) at each step and the buffers, as one JSON line on stdout."""
    import torch  # noqa: PLC0415

    from tpnet_gpu.pipeline import Pipeline  # noqa: PLC0415

    frames = np.load(path)
    peaks = {"import": _peak_mib()}
    pipe = Pipeline(frames.shape[1], frames.shape[2], device=device)
    peaks["built"] = _peak_mib()
    seconds, cpu_seconds = [], []
    for i in range(frames_run):
        start, cpu_start = time.perf_counter(), time.process_time()
        pipe.process(frames)
        seconds.append(time.perf_counter() - start)
        cpu_seconds.append(time.process_time() - cpu_start)
        peaks[f"frame{i + 1}"] = _peak_mib()
    buffers = buffer_bytes(pipe)
    print(json.dumps({"peak_mib": peaks, "seconds": seconds, "cpu_seconds": cpu_seconds, "buffers": buffers,
                      "threads": torch.get_num_threads()}))


def main(argv: list[str] | None = None) -> dict:
    parser = common.parser(__name__, __doc__)
    parser.add_argument("--height", type=int, default=1936)
    parser.add_argument("--width", type=int, default=2592)
    parser.add_argument("--frames", choices=("demo", "random"), default="demo")
    parser.add_argument("--frames-run", type=int, default=3, help="frames processed (default 3)")
    parser.add_argument("--frames-file", default=None,
                        help="a .npy of the frames: used when it exists, else the frames are made and kept there")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = args.frames_file or str(Path(tmp) / "frames.npy")
        if not Path(path).exists():
            log(f"making {args.frames} frames {args.width}x{args.height}")
            subprocess.run([sys.executable, "-m", __spec__.name, "--child-frames", args.frames, str(args.height),
                            str(args.width), path], check=True)
        log("measuring in a fresh process")
        out = subprocess.run([sys.executable, "-m", __spec__.name, "--child-measure", path, str(args.frames_run),
                              args.device], check=True, capture_output=True, text=True).stdout
    child = json.loads(out.strip().splitlines()[-1])
    report = {"frame": {"width": args.width, "height": args.height, "frames": args.frames_file or args.frames},
              "device": args.device, "machine": common.machine_info(), **child}
    total = sum(child["buffers"].values())
    rows = [(name, f"{n / MIB:.1f}") for name, n in child["buffers"].items() if n >= MIB]
    print("\n".join(common.format_table(("buffer", "MiB"), rows + [("total", f"{total / MIB:.1f}")])))
    print("\n".join(common.format_table(("step", "peak RSS MiB"),
                                        [(k, f"{v:.0f}") for k, v in child["peak_mib"].items()])))
    for label in ("seconds", "cpu_seconds"):  # CPU seconds: all threads, less sensitive to a shared machine
        values = child[label]
        print(f"{label} per frame: median {statistics.median(values):.2f} (each: "
              + ", ".join(f"{v:.2f}" for v in values) + "; the first includes warm-up)")
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child-frames":
        _make_frames(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5])
    elif len(sys.argv) > 1 and sys.argv[1] == "--child-measure":
        _measure(sys.argv[2], int(sys.argv[3]), sys.argv[4])
    else:
        sys.exit(common.run(main))
