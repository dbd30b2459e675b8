"""Accuracy of the hand-crafted baseline against rendered ground truth, beside peers on the same tiles.

    python bench/bench_accuracy.py [--scenes 3] [--width 1024 --height 768] [--json out/bench_accuracy.json]

Scenes: the demo scene, then random scenes (seeded), rendered with realistic optics and noise. Ours: the
tile processor + strips/centre of mass/LMA + sweep and refinement (``tpnet_gpu.baseline.estimate``). Peers:
OpenCV StereoSGBM, OpenCV phaseCorrelate, scikit-image phase_cross_correlation (bench/peers.py). Per tile class
(tpnet_gpu/evaluation.py) the RMSE, median |error| and coverage; RMSE vs the 3x3 ground-truth spread (the
paper's Figure 8) as a PNG. Prints a table, saves JSON.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers  # noqa: E402
import report as report_tools  # noqa: E402

from tpnet_gpu.baseline.estimate import (  # noqa: E402
    BASELINE_CORRELATION, BaselineParams, consistency_pass, initial_targets, processor_correlator, refine)
from tpnet_gpu.camera import Rig  # noqa: E402
from tpnet_gpu.config import CorrelationConfig  # noqa: E402
from tpnet_gpu.processor import TileProcessor  # noqa: E402
from tpnet_gpu.scenes import Optics, Sensor, demo_scene, random_scene, render  # noqa: E402

def log(message: str) -> None:
    print(f"[bench_accuracy] {message}", file=sys.stderr, flush=True)


def run_scene(index: int, args, rig: Rig) -> dict:
    rng = np.random.default_rng([args.seed, index])
    scene = demo_scene(rig, seed=args.seed) if index == 0 else random_scene(rig, rng)
    start = time.perf_counter()
    rendered = render(scene, rig, optics=Optics(), sensor=Sensor(), supersample=2, seed=args.seed + index)
    log(f"scene {index} ({scene.name}) rendered in {time.perf_counter() - start:.1f} s")
    frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    shape = rendered.tile_disparity.shape
    out = {"gt": rendered.tile_disparity, "confidence": rendered.tile_confidence, "spread": rendered.tile_spread}

    params = BaselineParams()
    configs = {"baseline (G phase correlation)": BASELINE_CORRELATION,
               "baseline (as-coded colour weights)": CorrelationConfig(fat_zero=BASELINE_CORRELATION.fat_zero)}
    estimates = {}
    for name, config in configs.items():
        tp = TileProcessor(rig.height, rig.width, config=config, device=args.device)
        correlate = processor_correlator(tp, frames)
        start = time.perf_counter()
        target, _ = initial_targets(correlate, shape, params)
        est = consistency_pass(correlate, refine(correlate, target, params), params)
        estimates[name] = est.disparity
        log(f"  {name}: {time.perf_counter() - start:.1f} s, passes {np.bincount(est.passes.ravel()).tolist()}")
        if "initial" not in out:
            out["initial"] = target

    left = peers.grey(rendered.raws[0], rendered.sensor.black_level)
    right = peers.grey(rendered.raws[1], rendered.sensor.black_level)
    start = time.perf_counter()
    sgbm = peers.sgbm(left, right, float(np.nanmax(rendered.tile_disparity)))
    ty, tx = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    gt = rendered.tile_disparity
    # camera 0 sees the tile centre c at c + d/2 (x and y); SGBM's map is in camera 0's pixels
    estimates["opencv-StereoSGBM"] = peers.sample(sgbm, 8 * tx + 4 + gt / 2, 8 * ty + 4 + gt / 2)
    log(f"  SGBM: {time.perf_counter() - start:.1f} s")
    for name in peers.METHODS:
        start = time.perf_counter()
        estimates[name] = peers.tile_peer(name, left, right, out["initial"])
        log(f"  {name}: {time.perf_counter() - start:.1f} s")
    out["estimates"] = estimates
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=3)
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=768)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default="out/bench_accuracy.json")
    parser.add_argument("--png", default="out/bench_accuracy.png")
    args = parser.parse_args(argv)
    rig = Rig(width=args.width, height=args.height)
    scenes = [run_scene(i, args, rig) for i in range(args.scenes)]

    methods = list(scenes[0]["estimates"])
    title = (f"Disparity accuracy, {args.scenes} rendered scenes of {args.width}x{args.height} (quad, 258 mm, "
             f"noise on), tile classes: tpnet_gpu/evaluation.py")
    meta = {"bench": "accuracy", "scenes": args.scenes, "width": args.width, "height": args.height,
            "seed": args.seed, "machine": {"platform": platform.platform(), "python": platform.python_version()},
            "optics": str(Optics()), "sensor": str(Sensor())}
    report_tools.publish(scenes, methods, title, methods[0], meta, args.json, args.png, log=log)
    return 0


if __name__ == "__main__":
    sys.exit(main())
