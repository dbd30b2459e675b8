"""Two-surface tiles (``tpnet_gpu.disparity.two_surface``) on the held-out scenes' edge tiles.

The scenes of ``tpnet bench network`` (the demo scene, then random scenes; seeds ``--seed``+, 10000+ held out: the
fit's settings were not tuned on them), rendered at supersample 2, through the disparity engine and then the
two-surface fit at its disparities. Scored on the edge tiles (``evaluation.tile_classes``: the ground truth's 3x3
neighbourhood spans > 1 px) whose 16x16 window sees two surfaces of at least 10 % each (the renderer's
``tile_surfaces``: share, min, max disparity per surface). A surface is hit within ``--tolerance`` px when an
estimate lies in [min - tol, max + tol]. "both": the two reported disparities hit the window's two largest
surfaces, one each; "either": at least one of them does (for the engine's single disparity: it does; also counted
on the tiles the fit reports two, so the fit's "either" has a peer there). Flat tiles reported as two-surface are
false alarms.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import report as report_tools
from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity import DisparityEngine
from tpnet_gpu.disparity.two_surface import measure_surfaces
from tpnet_gpu.evaluation import MIN_SURFACE_SHARE, tile_classes
from tpnet_gpu.scenes import Sensor, render

log = common.logger("two_surface")


def hits(estimate: np.ndarray, surface: np.ndarray, tolerance: float) -> np.ndarray:
    """``estimate (N,)`` within ``tolerance`` of ``surface (N, 3)`` (share, min, max): in [min - tol, max + tol]."""
    with np.errstate(invalid="ignore"):
        return (estimate >= surface[:, 1] - tolerance) & (estimate <= surface[:, 2] + tolerance)


def score(fg, bg, single, surfaces, edge, flat, tolerance: float) -> dict:
    """Counts on the edge tiles with two surfaces of >= MIN_SURFACE_SHARE (see the module docstring)."""
    two_gt = edge & (surfaces[..., 1, 0] >= MIN_SURFACE_SHARE)
    s1, s2 = surfaces[two_gt][:, 0], surfaces[two_gt][:, 1]
    f, b, d = fg[two_gt], bg[two_gt], single[two_gt]
    reported = np.isfinite(f) & np.isfinite(b)
    f1, f2, b1, b2 = (hits(e, s, tolerance) for e, s in ((f, s1), (f, s2), (b, s1), (b, s2)))
    both = reported & ((f1 & b2) | (f2 & b1))
    either = reported & (f1 | f2 | b1 | b2)
    single_hit = hits(d, s1, tolerance) | hits(d, s2, tolerance)
    return {"edge_two_surface_tiles": int(two_gt.sum()), "reported_two": int(reported.sum()), "both": int(both.sum()),
            "either_of_two": int(either.sum()), "single_either": int(single_hit.sum()),
            "single_either_where_two": int((single_hit & reported).sum()),
            "flat_tiles": int(flat.sum()), "flat_reported_two": int((flat & np.isfinite(fg)).sum())}


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--scenes", type=int, default=4, help="scenes (the demo scene first)")
    parser.add_argument("--width", type=int, default=640, help="frame width, pixels (multiple of 8)")
    parser.add_argument("--height", type=int, default=480, help="frame height, pixels (multiple of 8)")
    parser.add_argument("--seed", type=int, default=10000, help="first scene seed (10000+: held out)")
    parser.add_argument("--supersample", type=int, default=2, help="the renderer's sub-pixel rays per axis")
    parser.add_argument("--tolerance", type=float, default=0.5, help="px: a surface is hit within this")
    parser.add_argument("--backend", default=None, help="tile-processor kernels (default: the library's)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=None, help="write the report here")
    args = parser.parse_args(argv)
    if args.scenes < 1 or not args.tolerance > 0:
        parser.error("--scenes: at least 1; --tolerance: > 0")
    rig = Rig(width=args.width, height=args.height)
    engine = DisparityEngine(rig.height, rig.width, rig=rig, device=args.device, backend=args.backend)
    per_scene, seconds = [], []
    for index in range(args.scenes):  # the scenes of bench_network (same seeds, same renderer settings)
        scene = report_tools.bench_scene(rig, args.seed, index)
        rendered = render(scene, rig, sensor=Sensor(), supersample=args.supersample, seed=args.seed + index)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        result = engine.run(frames)
        start = time.perf_counter()
        surfaces = measure_surfaces(engine, result.disparity)
        seconds.append(time.perf_counter() - start)
        classes = tile_classes(rendered.tile_disparity, rendered.tile_confidence, rendered.tile_spread)
        per_scene.append(score(surfaces.foreground.cpu().numpy(), surfaces.background.cpu().numpy(),
                               result.disparity.cpu().numpy(), rendered.tile_surfaces, classes["edge"],
                               classes["flat"], args.tolerance))
        log(f"scene {index} ({scene.name}): {per_scene[-1]}, fit {seconds[-1]:.2f} s")
    total = {k: int(sum(s[k] for s in per_scene)) for k in per_scene[0]}
    n = max(total["edge_two_surface_tiles"], 1)
    pct = lambda k, d=n: f"{100 * total[k] / max(d, 1):.1f} %"  # noqa: E731
    header = ["method", "edge tiles (2 surfaces)", "reported two", f"both within {args.tolerance:g} px",
              f"either within {args.tolerance:g} px", "flat tiles reported two"]
    rows = [["engine (one disparity)", str(total["edge_two_surface_tiles"]), "-", "0 %", pct("single_either"), "-"],
            ["engine, where the fit reports two", str(total["edge_two_surface_tiles"]), "-", "0 %",
             pct("single_either_where_two"), "-"],
            ["two-surface fit", str(total["edge_two_surface_tiles"]), pct("reported_two"), pct("both"),
             pct("either_of_two"), pct("flat_reported_two", total["flat_tiles"])]]
    table = [f"Two-surface tiles, {args.scenes} rendered scenes of {args.width}x{args.height} (seeds {args.seed}+), "
             f"edge tiles whose window sees two surfaces of >= {100 * MIN_SURFACE_SHARE:.0f} %; fit "
             f"{np.median(seconds):.2f} s / frame (median)", ""] + common.format_table(header, rows)
    print("\n".join(table))
    report = {"bench": "two_surface", "scenes": args.scenes, "width": args.width, "height": args.height,
              "seed": args.seed, "tolerance": args.tolerance, "totals": total, "per_scene": per_scene,
              "fit_seconds": seconds, "machine": common.machine_info(), "table": table}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    torch.set_num_threads(1)
    sys.exit(common.run(main))
