"""Motion vectors vs ground truth (``tpnet_gpu.flow``): rendered scenes, the rig moved between two frames.

Per scene (the demo scene, then random scenes; seeds ``--seed``+, held out: the flow's settings were chosen on a
scene of seed 7) and motion, both frames are rendered (supersample 1, sensor noise on) and the flow of camera 0
alone and of the four cameras combined is measured and compared with the renderer's ground truth (the same world
points projected at both times, ``scenes.motion.tile_flow``). The rig is referenced to camera 0, so the
renderer's per-tile truth (textured, one object) is camera 0's tile grid; the combined flow aligns the cameras
by the disparity engine's maps of both frames (``flow_align``) and is the virtual camera's, camera 0's: scored
against camera 0's truth too. Seconds per pair include the engine's two maps for the combined flow. "one way":
camera 0 without the backward check (``FlowConfig.backward``), its peer for the check's gain and cost.
Scored on textured single-object tiles (the renderer's tile confidence > 0.5) inside the border ring: median
|error|, RMSE of the inliers (|error| <= 1 px), gross (|error| > 1 px) share of the measured ones, coverage
(measured share).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import report as report_tools
from tpnet_gpu.camera import Rig
from tpnet_gpu.flow import FlowConfig, FlowEstimator
from tpnet_gpu.scenes import Sensor, render
from tpnet_gpu.scenes.motion import RigMotion, moved_scene, tile_flow

log = common.logger("flow")
MOTIONS = {  # rig motions between the frames: mm (x right, y up, z toward the viewer), radians (tilt, pan, roll)
    "sideways 100 mm": RigMotion(translation=(100.0, 0.0, 0.0)),
    "forward 2 m": RigMotion(translation=(0.0, 0.0, -2000.0)),
    "pan 1 mrad + tilt 0.5 mrad": RigMotion(rotation=(0.0005, 0.001, 0.0)),
    "roll 10 mrad": RigMotion(rotation=(0.0, 0.0, 0.01)),
    "up 150 mm + pan 2 mrad": RigMotion(translation=(0.0, 150.0, 0.0), rotation=(0.0, 0.002, 0.0)),
}
TEXTURED = 0.5  # renderer tile confidence above which a tile is textured and sees one object
GROSS = 1.0  # px


def score(flow: np.ndarray, gt: np.ndarray, scored: np.ndarray) -> dict:
    """Median |error|, inlier RMSE, gross share and coverage of ``flow`` ``(ty, tx, 2)`` on the ``scored`` tiles."""
    error = np.linalg.norm(flow - gt, axis=-1)[scored]
    measured = np.isfinite(error)
    e = error[measured]
    inliers = e[e <= GROSS]
    return {"tiles": int(scored.sum()), "coverage": float(measured.mean()) if measured.size else float("nan"),
            "median": float(np.median(e)) if e.size else float("nan"),
            "rmse_inliers": float(np.sqrt(np.mean(inliers**2))) if inliers.size else float("nan"),
            "gross": float((e > GROSS).mean()) if e.size else float("nan")}


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--scenes", type=int, default=2, help="scenes (the demo scene first)")
    parser.add_argument("--width", type=int, default=320, help="frame width, pixels (multiple of 8)")
    parser.add_argument("--height", type=int, default=240, help="frame height, pixels (multiple of 8)")
    parser.add_argument("--seed", type=int, default=10000, help="first scene seed")
    parser.add_argument("--motions", default=",".join(MOTIONS), help=f"comma-separated, of: {', '.join(MOTIONS)}")
    parser.add_argument("--backend", default="warp", help="tile-processor kernels")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=None, help="write the report here")
    args = parser.parse_args(argv)
    motions = [m.strip() for m in args.motions.split(",") if m.strip()]
    if args.scenes < 1 or not motions or any(m not in MOTIONS for m in motions):
        parser.error(f"--scenes: at least 1; --motions: of {list(MOTIONS)}, got {args.motions!r}")
    rig = Rig(width=args.width, height=args.height).referenced_to(0)  # scored on camera 0's own tile grid
    estimators = {"camera 0": FlowEstimator(rig.height, rig.width, cams=1, device=args.device, backend=args.backend),
                  "camera 0, one way": FlowEstimator(rig.height, rig.width, cams=1, config=FlowConfig(backward=False),
                                                     device=args.device, backend=args.backend),
                  "4 cameras": FlowEstimator(rig.height, rig.width, cams=4, rig=rig, device=args.device,
                                             backend=args.backend)}
    rows = {(m, e): [] for m in motions for e in estimators}
    seconds = {e: [] for e in estimators}
    for index in range(args.scenes):
        seed = args.seed + index
        scene = report_tools.bench_scene(rig, args.seed, index)
        first = render(scene, rig, sensor=Sensor(), supersample=1, seed=seed)
        textured = np.zeros(first.tile_confidence.shape, dtype=bool)  # the border ring's windows are off the image
        textured[1:-1, 1:-1] = first.tile_confidence[1:-1, 1:-1] > TEXTURED
        for name in motions:
            motion = MOTIONS[name]
            second = render(moved_scene(scene, motion), rig, sensor=Sensor(), supersample=1, seed=seed + 50000)
            truth = tile_flow(scene, rig, motion, 0)  # camera 0's: the virtual camera's
            a = first.raws.astype(np.float32) - first.sensor.black_level
            b = second.raws.astype(np.float32) - second.sensor.black_level
            for est_name, est in estimators.items():
                cams = est.cams
                start = time.perf_counter()
                result = est.estimate(a[:cams], b[:cams])
                seconds[est_name].append(time.perf_counter() - start)
                rows[(name, est_name)].append(score(result.flow.cpu().numpy(), truth, textured))
            log(f"scene {index} ({scene.name}), {name}: done")
    stats = {}
    for (name, est_name), per_scene in rows.items():
        tiles = np.array([s["tiles"] for s in per_scene], dtype=float)

        def pooled(key, per_scene=per_scene, tiles=tiles):  # tile-weighted over scenes; medians: median of scenes
            values = np.array([s[key] for s in per_scene], dtype=float)
            ok = np.isfinite(values)
            return float(np.average(values[ok], weights=tiles[ok])) if ok.any() else float("nan")

        medians = [s["median"] for s in per_scene if np.isfinite(s["median"])]
        stats[f"{name} | {est_name}"] = {"median": float(np.median(medians)) if medians else float("nan"),
                                         "rmse_inliers": pooled("rmse_inliers"), "gross": pooled("gross"),
                                         "coverage": pooled("coverage"), "tiles": int(tiles.sum())}
    header = ["motion | flow of", "median px", "rmse-in px", "gross > 1 px", "coverage", "tiles"]
    table = [f"Flow vs ground truth, {args.scenes} rendered scene(s) of {args.width}x{args.height} (seeds "
             f"{args.seed}+), textured single-object tiles; s / pair: " + ", ".join(
                 f"{k} {np.median(v):.2f}" for k, v in seconds.items()), ""]
    table += common.format_table(header, [[k, f"{v['median']:.3f}", f"{v['rmse_inliers']:.3f}",
                                           f"{100 * v['gross']:.1f} %", f"{100 * v['coverage']:.0f} %",
                                           str(v["tiles"])] for k, v in stats.items()])
    print("\n".join(table))
    report = {"bench": "flow", "scenes": args.scenes, "width": args.width, "height": args.height, "seed": args.seed,
              "motions": motions, "stats": stats, "per_scene": {f"{m} | {e}": v for (m, e), v in rows.items()},
              "seconds_per_pair": {k: float(np.median(v)) for k, v in seconds.items()},
              "machine": common.machine_info(), "table": table}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    torch.set_num_threads(1)
    sys.exit(common.run(main))
