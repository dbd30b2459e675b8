"""Accuracy of the hand-crafted baseline against rendered ground truth, beside peers on the same tiles.

    tpnet bench accuracy [--scenes 3] [--width 1024 --height 768] [--peer-passes 4] [--json out/bench_accuracy.json]
                         [--png out/bench_accuracy.png]
    python -m tpnet_gpu.bench.accuracy.bench_accuracy [same options]

Scenes: the demo scene, then random scenes (seeded), rendered with realistic optics and noise. Ours: the
tile processor + strips/centre of mass/LMA + sweep and refinement (``tpnet_gpu.baseline.estimate``). Peers:
OpenCV StereoSGBM, OpenCV phaseCorrelate, scikit-image phase_cross_correlation (bench/twins/peers.py). Per tile class
(tpnet_gpu/evaluation.py) the strict and either-surface gross shares, RMSE on each method's own inliers and on
the tiles the first baseline gets right, new gross errors, coverage, the baselines' confidence ranking and each
method's seconds per frame (bench/accuracy/report.py); RMSE vs the 3x3 ground-truth spread (the paper's Figure 8) as a
PNG. Prints a table, saves JSON. Needs the optional ``bench`` extra (OpenCV, matplotlib): ``pip install -e
".[bench]"``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from tpnet_gpu.baseline.estimate import (
    BASELINE_CORRELATION, BaselineParams, consistency_pass, initial_targets, processor_correlator, refine)
from tpnet_gpu.camera import Rig
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Optics, Sensor, render

from tpnet_gpu.bench import common
from tpnet_gpu.bench.twins import peers
from tpnet_gpu.bench.accuracy import report as report_tools

log = common.logger("bench_accuracy")


def run_scene(index: int, args, rig: Rig) -> dict:
    scene = report_tools.bench_scene(rig, args.seed, index)
    start = time.perf_counter()
    rendered = render(scene, rig, optics=Optics(), sensor=Sensor(), supersample=2, seed=args.seed + index)
    log(f"scene {index} ({scene.name}) rendered in {time.perf_counter() - start:.1f} s")
    frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    shape = rendered.tile_disparity.shape
    out = {"gt": rendered.tile_disparity, "confidence": rendered.tile_confidence, "spread": rendered.tile_spread,
           "surfaces": rendered.tile_surfaces, "confidences": {}, "per_frame": {}}

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
        out["confidences"][name] = est.strength
        seconds = time.perf_counter() - start
        out["per_frame"][name] = {"seconds": seconds}
        log(f"  {name}: {seconds:.1f} s, passes {np.bincount(est.passes.ravel()).tolist()}")
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
    seconds = time.perf_counter() - start
    out["per_frame"]["opencv-StereoSGBM"] = {"seconds": seconds}
    log(f"  SGBM: {seconds:.1f} s")
    for name in peers.METHODS:
        start = time.perf_counter()
        estimates[name] = peers.tile_peer(name, left, right, out["initial"], passes=args.peer_passes)
        seconds = time.perf_counter() - start
        out["per_frame"][name] = {"seconds": seconds}
        log(f"  {name}: {seconds:.1f} s")
    out["estimates"] = estimates
    return out


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    report_tools.scene_arguments(parser, "accuracy", scenes=3, width=1024, height=768, seed=100)
    parser.add_argument("--peer-passes", type=int, default=4,
                        help="re-centring passes of the per-tile phase-correlation peers (default 4)")
    args = parser.parse_args(argv)
    if args.scenes < 1 or args.peer_passes < 1:
        parser.error("--scenes, --peer-passes: expected at least 1")
    common.require_extras("cv2", *(("matplotlib",) if args.png else ()))
    rig = Rig(width=args.width, height=args.height)
    scenes = [run_scene(i, args, rig) for i in range(args.scenes)]

    methods = list(scenes[0]["estimates"])
    title = (f"Disparity accuracy, {args.scenes} rendered scenes of {args.width}x{args.height} (quad, 258 mm, "
             f"noise on), tile classes: tpnet_gpu/evaluation.py")
    meta = {"bench": "accuracy", "scenes": args.scenes, "width": args.width, "height": args.height,
            "seed": args.seed, "peer_passes": args.peer_passes, "machine": common.machine_info(),
            "optics": str(Optics()), "sensor": str(Sensor())}
    return report_tools.publish(scenes, methods, title, methods[0], meta, args.json, args.png, log=log)


if __name__ == "__main__":
    sys.exit(common.run(main))
