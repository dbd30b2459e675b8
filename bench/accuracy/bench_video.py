"""A video: rendered moving sequences through ``Pipeline.stream``, every frame searched in full against frames that
follow the one before (``stream(follow=True)``, ``disparity.follow``), in the same run.

    tpnet bench video [--sequences 2] [--frames 8] [--width 640 --height 480] [--seed 10000] [--pair] [--json ...]
    python -m tpnet_gpu.bench.accuracy.bench_video [same options]

Each sequence is a scene of ``tpnet bench network`` (the demo scene, then random ones; seeds 10000+ held out)
seen by a rig that moves every frame (``scenes.motion.RigMotion``: forward ``--step-mm`` and sideways a fifth of
it, panning 0.03 degrees), rendered with exact ground truth: Bayer frames of the quad, or with ``--pair`` mono
frames of the shipped binocular rig referenced to its first camera, as ``tpnet process LEFT_DIR RIGHT_DIR``
reads image pairs (``rendered_pairs.pair_rig``, ``Rig.referenced_to(0)``; the ground truth is that camera's),
which the pipeline checks as a stereo pair (cross-check engine and per-pixel step; both engines follow). Per
method: engine tile passes per frame (the frames that follow: all but each sequence's first), gross share (> 1 px,
all tiles with ground truth, strict), own-inlier RMSE and coverage over those frames, and the seconds per frame
(median). The followed frames' figures
against the per-frame ones are the ratio the issue asks for (accuracy within 2 %: gross difference in points).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from tpnet_gpu import evaluation
from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import report as report_tools
from tpnet_gpu.bench.accuracy.rendered_pairs import pair_rig
from tpnet_gpu.camera import Rig
from tpnet_gpu.config import PipelineConfig
from tpnet_gpu.disparity.follow import REFRESH
from tpnet_gpu.pipeline import Pipeline
from tpnet_gpu.scenes import Sensor, render
from tpnet_gpu.scenes.motion import RigMotion, moved_scene

log = common.logger("video")


def sequence(rig: Rig, seed: int, index: int, frames: int, step_mm: float, cfa: str | None = "GRBG") -> tuple[
        list, list]:
    """``frames`` raw frames ``(cams, H, W)`` of scene ``index`` as the moving rig sees it, and each frame's ground
    truth ``(tile_disparity, tile_confidence, tile_spread)``."""
    scene = report_tools.bench_scene(rig, seed, index)
    motion = RigMotion(translation=(step_mm / 5.0, 0.0, -step_mm), rotation=(0.0, np.radians(0.03), 0.0))
    raws, truth = [], []
    for k in range(frames):
        rendered = render(scene, rig, sensor=Sensor(cfa=cfa), supersample=1, seed=seed + 100 * index + k)
        raws.append(rendered.raws.astype(np.float32) - rendered.sensor.black_level)
        truth.append((rendered.tile_disparity, rendered.tile_confidence, rendered.tile_spread))
        scene = moved_scene(scene, motion)
    return raws, truth


def run_method(pipeline: Pipeline, raws: list, truth: list, follow: bool) -> list[dict]:
    """Per frame: passes, seconds and the error statistics over all tiles with ground truth."""
    out, stream = [], pipeline.stream(raws, follow=follow)
    for k in range(len(raws)):
        start = time.perf_counter()
        result = next(stream)
        seconds = time.perf_counter() - start
        gt, confidence, spread = truth[k]
        classes = evaluation.tile_classes(gt, confidence, spread)
        stats = evaluation.error_stats(result.disparity.cpu().numpy().astype(np.float64), gt, classes["all"])
        out.append({"passes": float(result.tile_passes), "seconds": seconds, **{k2: float(v) for k2, v in
                                                                               stats.items()}})
    return out


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--sequences", type=int, default=2, help="sequences (the demo scene first)")
    parser.add_argument("--frames", type=int, default=8, help=f"frames per sequence (<= {REFRESH}: one search)")
    parser.add_argument("--width", type=int, default=640, help="frame width, pixels (multiple of 8)")
    parser.add_argument("--height", type=int, default=480, help="frame height, pixels (multiple of 8)")
    parser.add_argument("--seed", type=int, default=10000, help="first scene seed (10000+: held out)")
    parser.add_argument("--step-mm", type=float, default=150.0, help="the rig's forward step per frame, mm")
    parser.add_argument("--pair", action="store_true", help="mono frames of the binocular rig (a stereo pair, "
                        "checked as one) instead of the quad's Bayer frames")
    parser.add_argument("--backend", default=None, help="tile-processor kernels (default: the library's)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=None, help="write the report here")
    args = parser.parse_args(argv)
    if args.sequences < 1 or args.frames < 2 or not np.isfinite(args.step_mm):
        parser.error("--sequences: at least 1; --frames: at least 2; --step-mm: a finite number")
    # a pair as `tpnet process` reads two images: camera 0 the reference (the per-pixel step needs a camera there)
    rig = pair_rig(args.width, args.height).referenced_to(0) if args.pair else Rig(width=args.width, height=args.height)
    cfa = None if args.pair else Sensor().cfa
    pipeline = Pipeline(rig.height, rig.width, rig=rig, cfa=cfa, device=args.device, backend=args.backend,
                        config=PipelineConfig(textures=False))
    per = {"every frame searched": [], "following the frame before": []}
    for index in range(args.sequences):
        raws, truth = sequence(rig, args.seed, index, args.frames, args.step_mm, cfa)
        pipeline.process(raws[0])  # warm-up: kernels loaded, buffers touched
        for name, follow in (("every frame searched", False), ("following the frame before", True)):
            frames = run_method(pipeline, raws, truth, follow)
            per[name] += frames[1:]  # the frames that follow (each sequence's first is searched either way)
            log(f"sequence {index}, {name}: passes {[round(f['passes'], 2) for f in frames]}")
    header = ["method", "frames", "tile passes / frame", "gross > 1 px", "own-inlier RMSE px", "coverage",
              "s / frame (median)"]
    rows, summary = [], {}
    for name, frames in per.items():
        summary[name] = {"frames": len(frames), "passes": float(np.mean([f["passes"] for f in frames])),
                         "gross": float(np.mean([f["gross"] for f in frames])),
                         "rmse_inliers": float(np.mean([f["rmse_inliers"] for f in frames])),
                         "coverage": float(np.mean([f["coverage"] for f in frames])),
                         "seconds": float(np.median([f["seconds"] for f in frames]))}
        s = summary[name]
        rows.append([name, str(s["frames"]), f"{s['passes']:.2f}", f"{100 * s['gross']:.2f} %",
                     f"{s['rmse_inliers']:.4f}", f"{100 * s['coverage']:.1f} %", f"{s['seconds']:.2f}"])
    kind = "mono pair" if args.pair else "Bayer quad"
    table = [f"Video ({kind}): {args.sequences} moving sequences of {args.frames} frames, {args.width}x{args.height} "
             f"(seeds {args.seed}+; step {args.step_mm:g} mm), the frames after each first", ""] + \
        common.format_table(header, rows)
    print("\n".join(table))
    report = {"bench": "video", "rig": "binocular, mono" if args.pair else "quad, Bayer",
              "per_pixel": pipeline.per_pixel,
              "sequences": args.sequences, "frames": args.frames, "width": args.width,
              "height": args.height, "seed": args.seed, "step_mm": args.step_mm, "summary": summary,
              "per_frame": per, "machine": common.machine_info(), "table": table}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
