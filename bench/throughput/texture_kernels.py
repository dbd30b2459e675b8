"""Per-kernel time of the Taichi texture step (issue 14): each launch of kernels/taichi_texture.py timed with
``ti.sync`` on either side, summed per kernel over one ``TileProcessor.texture()`` call, medians over repeats.

    python -m tpnet_gpu.bench.throughput.texture_kernels [--frames FILE.npy] [--height H --width W] [--repeat N]

``--frames``: a ``(cams, H, W)`` float32 Bayer GRBG frame (e.g. a cached demo frame); otherwise uniform random
raw values of the given size. The processor uses ``config.BASELINE_CORRELATION`` at target disparity 0. Wrap a
5 MPix run in ``flock /tmp/bigrun.lock`` on shared machines (~3 GB).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import taichi as ti

from tpnet_gpu import config
from tpnet_gpu.kernels import taichi_texture
from tpnet_gpu.processor import TileProcessor

KERNELS = ("texture_imclt", "texture_demosaic", "texture_combine", "overlap_add")


def _timed(name: str, kernel, times: dict[str, float]):
    def launch(*args):
        ti.sync()
        start = time.perf_counter()
        kernel(*args)
        ti.sync()
        times[name] = times.get(name, 0.0) + time.perf_counter() - start
    return launch


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", help="(cams, H, W) float32 .npy, Bayer GRBG")
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    if args.frames:
        frames = np.ascontiguousarray(np.load(args.frames), dtype=np.float32)  # (cams, H, W)
    else:
        frames = np.random.default_rng(0).integers(0, 4096, (4, args.height, args.width)).astype(np.float32)
    _, height, width = frames.shape
    tp = TileProcessor(height, width, cfa="GRBG", textures=True, config=config.BASELINE_CORRELATION,
                       backend="taichi")
    times: dict[str, float] = {}
    for name in KERNELS:  # the backend calls them through the module: wrap them there
        if hasattr(taichi_texture, name):
            setattr(taichi_texture, name, _timed(name, getattr(taichi_texture, name), times))
    tp.process(frames, 0.0)  # compiles
    steps, per_kernel = [], {}
    for _ in range(args.repeat):
        times.clear()
        start = time.perf_counter()
        tp.texture()
        ti.sync()
        steps.append(time.perf_counter() - start)
        for name, seconds in times.items():
            per_kernel.setdefault(name, []).append(seconds)
    print(f"{width}x{height} texture step: median {statistics.median(steps):.3f} s of {args.repeat} "
          f"({', '.join(f'{s:.3f}' for s in steps)})")
    for name, runs in per_kernel.items():
        print(f"  {name:18s} median {statistics.median(runs):.3f} s")


if __name__ == "__main__":
    main()
