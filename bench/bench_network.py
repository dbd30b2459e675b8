"""TPNET against the hand-crafted LMA baseline on held-out rendered scenes (the paper's claim: 2x lower error).

    tpnet bench network [--scenes 4] [--width 640 --height 480] [--passes 3] [--weights PATH] [--json ...] [--png ...]
    python -m tpnet_gpu.bench.bench_network [same options]

Scenes are rendered fresh with seeds no training scene uses (``--seed`` 10000+), the demo scene first. The
baseline measures every tile (sweep + refinement); the network then reads the tile processor's layers at the
baseline's disparities (tiles the baseline rejected start from their nearest measured neighbour) and predicts
the residual; each further pass re-correlates at the previous pass's disparity (one row per pass count, up
to ``--passes``). All are scored on the same tiles and classes (tpnet_gpu/evaluation.py), and on the tiles
the baseline gets within 1 px (``rmse-ref``, the paper's protocol). Table + JSON + PNG (the PNG needs matplotlib,
of the optional ``bench`` extra).
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np
import torch

from tpnet_gpu.baseline.estimate import BASELINE_CORRELATION, estimate, processor_correlator
from tpnet_gpu.camera import Rig
from tpnet_gpu.net import infer
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Sensor, demo_scene, random_scene, render

from . import common
from . import report as report_tools

log = common.logger("bench_network")


def fill_nearest(values: np.ndarray) -> np.ndarray:
    """NaNs replaced by the nearest finite value (scipy distance transform); all-NaN gives zeros."""
    from scipy import ndimage

    bad = ~np.isfinite(values)
    if bad.all():
        return np.zeros_like(values)
    index = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
    return values[tuple(index)]


def pass_name(n: int) -> str:
    return f"TPNET ({n} pass{'es' if n > 1 else ''})"


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    report_tools.scene_arguments(parser, "network", scenes=4, width=640, height=480, seed=10000)
    parser.add_argument("--weights", default=None, help="TPNET weights (default: the shipped ones)")
    parser.add_argument("--passes", type=int, default=3, help="most network passes (re-measured at its own output)")
    args = parser.parse_args(argv)
    if args.scenes < 1 or args.passes < 1:
        parser.error("--scenes, --passes: expected at least 1")
    if args.png:
        common.require_extras("matplotlib")

    rig = Rig(width=args.width, height=args.height)
    model = infer.load(args.weights, device=args.device)
    net_tp = TileProcessor(rig.height, rig.width, config=infer.correlation(args.weights), device=args.device)
    base_tp = TileProcessor(rig.height, rig.width, config=BASELINE_CORRELATION, device=args.device)
    scenes = []
    for index in range(args.scenes):
        rng = np.random.default_rng([args.seed, index])
        scene = demo_scene(rig, seed=args.seed) if index == 0 else random_scene(rig, rng)
        rendered = render(scene, rig, sensor=Sensor(), supersample=2, seed=args.seed + index)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        shape = rendered.tile_disparity.shape
        start = time.perf_counter()
        base_estimate = estimate(processor_correlator(base_tp, frames), shape)
        base = base_estimate.disparity
        t_base = time.perf_counter() - start
        costs = {"LMA baseline": {"seconds": t_base}}  # TPNET's seconds include the baseline it starts from
        target = torch.from_numpy(fill_nearest(base).astype(np.float32)).to(net_tp.torch_device)
        estimates = {"LMA baseline": base}
        start = time.perf_counter()
        for n in range(1, args.passes + 1):
            layers = net_tp.process(frames, target).layers
            target = infer.infer(model, layers, target, grid=shape)
            net = target.cpu().numpy().astype(np.float64)
            net[~np.isfinite(base)] = np.nan  # scored on the tiles the baseline measured
            estimates[pass_name(n)] = net
            costs[pass_name(n)] = {"seconds": t_base + time.perf_counter() - start}
        t_net = time.perf_counter() - start
        log(f"scene {index} ({scene.name}): baseline {t_base:.1f} s, network ({args.passes} passes) {t_net:.2f} s")
        scenes.append({"gt": rendered.tile_disparity, "confidence": rendered.tile_confidence,
                       "spread": rendered.tile_spread, "estimates": estimates, "surfaces": rendered.tile_surfaces,
                       "confidences": {"LMA baseline": base_estimate.strength}, "per_frame": costs})

    methods = ["LMA baseline"] + [pass_name(n) for n in range(1, args.passes + 1)]
    title = (f"TPNET vs the LMA baseline, {args.scenes} held-out rendered scenes of {args.width}x{args.height} "
             f"(seeds {args.seed}+), weights {args.weights or infer.DEFAULT_WEIGHTS.name}")
    meta = {"bench": "network", "scenes": args.scenes, "width": args.width, "height": args.height,
            "seed": args.seed, "passes": args.passes, "machine": platform.platform()}
    return report_tools.publish(scenes, methods, title, "LMA baseline", meta, args.json, args.png, log=log)


if __name__ == "__main__":
    sys.exit(common.run(main))
