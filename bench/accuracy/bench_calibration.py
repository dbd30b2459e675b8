"""Field calibration against a known misalignment: the LMA fit and gradient descent through the differentiable
tile processor, and the disparity engine's errors with the ideal, true and calibrated rigs.

    tpnet bench calibration [--levels 0.4,2.5] [--scenes 2] [--width 320 --height 240] [--rounds 4]
                            [--gradient-steps 20] [--json out/bench_calibration.json]

Per misalignment level (px at the frame edge): a random gauge-free correction vector of that size
(``tpnet_gpu.calibration.synthetic``), random scenes rendered with it (supersample 1, noise on), both methods
started from the ideal rig. Reported: the largest frame-edge misalignment left (px, ``edge_misalignment``, gauge
removed) for the ideal rig, LMA and gradient, their seconds; and the engine's flat-tile strict gross share and
inlier RMSE (tpnet_gpu/evaluation.py) on the same scenes (field calibration is per scene set) with the ideal,
true, LMA and gradient rigs (medians over the scenes). Prints a table, saves JSON.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from tpnet_gpu import evaluation
from tpnet_gpu.calibration import CalibrationConfig, Frame, calibrate, edge_misalignment, model
from tpnet_gpu.calibration.synthetic import misalignment
from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.scenes import random_scene, render

from tpnet_gpu.bench import common

log = common.logger("bench_calibration")
RIGS = ("ideal", "true", "lma", "gradient")


def _disparity_errors(rendered, frames, rig) -> dict:
    engine = DisparityEngine(rig.height, rig.width, rig=rig, device="cpu")
    estimate = engine.run(frames).disparity.cpu().numpy()
    flat = evaluation.tile_classes(rendered.tile_disparity, rendered.tile_confidence, rendered.tile_spread)["flat"]
    stats = evaluation.error_stats(estimate, rendered.tile_disparity, flat)
    return {"gross": stats["gross"], "rmse_inliers": stats["rmse_inliers"], "tiles": stats["tiles"]}


def run_level(level: float, args) -> dict:
    ideal = Rig(width=args.width, height=args.height)
    truth = misalignment(ideal, level, seed=args.seed)
    true_rig = model.with_extrinsics(ideal, truth)
    rendered = [render(random_scene(ideal, np.random.default_rng([args.seed, i])), true_rig, supersample=1,
                       seed=args.seed + i) for i in range(args.scenes)]
    frames = [Frame(r.raws.astype(np.float32) - r.sensor.black_level) for r in rendered]
    config = CalibrationConfig(rounds=args.rounds, gradient_steps=args.gradient_steps)
    out = {"level_px": level, "truth": truth.tolist(), "edge_px": {"ideal": edge_misalignment(ideal, 0 * truth, truth)},
           "seconds": {}, "rounds": {}, "extrinsics": {}}
    rigs = {"ideal": ideal, "true": true_rig}
    for method in ("lma", "gradient"):
        result = calibrate(frames, ideal, method=method, config=config, device="cpu", log=log)
        rigs[method] = result.rig
        out["edge_px"][method] = edge_misalignment(ideal, result.extrinsics, truth)
        out["seconds"][method] = result.seconds
        out["rounds"][method] = result.rounds
        out["extrinsics"][method] = result.extrinsics.tolist()
        log(f"{level} px, {method}: edge error {out['edge_px'][method]:.3f} px in {result.seconds:.1f} s")
    out["disparity"] = {}
    for name in RIGS:
        per_scene = [_disparity_errors(r, f.frames, rigs[name]) for r, f in zip(rendered, frames)]
        out["disparity"][name] = {k: float(np.median([s[k] for s in per_scene])) for k in ("gross", "rmse_inliers")}
    return out


def table(levels: list[dict]) -> list[str]:
    rows = [[f"{lv['level_px']:g}", f"{lv['edge_px']['ideal']:.3f}", f"{lv['edge_px']['lma']:.3f}",
             f"{lv['edge_px']['gradient']:.3f}", f"{lv['seconds']['lma']:.1f}", f"{lv['seconds']['gradient']:.1f}"]
            for lv in levels]
    lines = common.format_table(["misalignment px", "edge err ideal", "edge err LMA", "edge err gradient",
                                 "LMA s", "gradient s"], rows)
    rows = [[f"{lv['level_px']:g}"] + [f"{100 * lv['disparity'][n]['gross']:.2f} / {lv['disparity'][n]['rmse_inliers']:.3f}"
                                       for n in RIGS] for lv in levels]
    return lines + [""] + common.format_table(["flat gross % / inlier RMSE px"] + [f"{n} rig" for n in RIGS], rows)


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--levels", default="0.4,2.5", help="misalignments at the frame edge, px, comma-separated")
    parser.add_argument("--scenes", type=int, default=2, help="random scenes per level")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--rounds", type=int, default=4, help="measure + fit rounds of each method")
    parser.add_argument("--gradient-steps", type=int, default=10, help="L-BFGS iterations per gradient round")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", default="out/bench_calibration.json")
    args = parser.parse_args(argv)
    try:
        levels = [float(v) for v in args.levels.split(",")]
    except ValueError:
        parser.error(f"--levels: expected comma-separated numbers of pixels, got {args.levels!r}")
    if args.scenes < 1 or args.rounds < 1 or args.gradient_steps < 1 or not all(v > 0 for v in levels):
        parser.error("--scenes, --rounds, --gradient-steps: expected at least 1; --levels: positive")
    start = time.perf_counter()
    results = [run_level(v, args) for v in levels]
    lines = table(results)
    title = (f"Field calibration, {args.scenes} random {args.width}x{args.height} scene(s) per level (quad, noise on, "
             f"supersample 1), {args.rounds} rounds, from the ideal rig")
    print(title)
    print("\n".join(lines))
    report = {"bench": "calibration", "title": title, "width": args.width, "height": args.height,
              "scenes": args.scenes, "seed": args.seed, "rounds": args.rounds, "gradient_steps": args.gradient_steps,
              "levels": results, "table": lines, "seconds": time.perf_counter() - start,
              "machine": common.machine_info()}
    common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
