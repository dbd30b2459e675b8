"""TPNET's context step (net/context.py) beside its alternatives, on rendered scenes neither training nor held out.

    tpnet bench network_context [--scenes 32] [--check-from 16] [--width 640 --height 480] [--seed 20000]
                                [--weights PATH] [--json ...]
    python -m tpnet_gpu.bench.accuracy.bench_network_context [same options]

Scenes are drawn as ``bench_network_limits`` draws them (random scenes of ``[seed, index]``, seeds 20000+, never
the held-out 10000+). Scenes ``0 .. --check-from - 1`` are the tuning scenes (where the step was chosen), the rest
the check scenes (where the choice was confirmed). Per scene: the disparity engine, TPNET's passes read at its
answer (its first-stage answer where it measured none, as the pipeline runs them), and context steps applied to
the network's output on the engine's measured tiles:

* **shipped**: ``context_step``, the strength-weighted mean of the 5x5 tiles within 0.5 px of the tile itself;
* **variants** (each one change from the shipped step): another band, a 3x3 window (v4's step), no weights, the
  engine's confidence as weights, the surface taken as the tiles within the band of the window's median instead
  of the tile's own value, two-depth tiles (``grid.two_depth``) left alone, and the plain 3x3 median
  (network.md §10's analysis: where the tile lies within 0.5 px of its window's median, the median);
* **between passes**: the shipped step after the first pass, then the second pass (and the step again);
* **engine + shipped**: the step on the engine's own answer (the peer: what the step gives without the network).

Scored per class (tpnet_gpu/evaluation.py) on each method's own inliers (RMSE, and its ratio to the engine's),
with the strict gross tiles (> 1 px, a count), the either-surface gross share and the tiles the engine has right
that the method makes gross.
"""

from __future__ import annotations

import platform
import sys

import numpy as np
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity import DisparityEngine
from tpnet_gpu.disparity.grid import neighbourhood, two_depth, weighted_mean
from tpnet_gpu.evaluation import error_stats, is_gross, reference_inliers, tile_classes
from tpnet_gpu.net import infer
from tpnet_gpu.net.context import CONTEXT_BAND, CONTEXT_SIZE, context_step
from tpnet_gpu.net.layers import NetworkLayers
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Sensor, random_scene, render

from tpnet_gpu.bench import common

log = common.logger("bench_network_context")

CLASSES = ("flat", "edge", "all")
SHIPPED = "TPNET + shipped step"


def variant(disparity: torch.Tensor, weight: torch.Tensor, *, size: int = CONTEXT_SIZE, band: float = CONTEXT_BAND,
            surface: str = "own", skip: torch.Tensor | None = None) -> torch.Tensor:
    """A context step of the family the shipped one belongs to: ``disparity (ty, tx)`` (NaN = none), each finite
    tile replaced by the ``weight``-weighted mean of its ``size`` x ``size`` tiles on its surface: those within
    ``band`` of the tile (``surface`` "own") or of the window's median ("median": only tiles within ``band`` of it
    move); ``surface`` "median only" takes the median itself (network.md §10). Tiles of ``skip`` keep their value."""
    w = neighbourhood(disparity, size)
    median = torch.nanmedian(w, dim=-1).values
    centre = disparity if surface == "own" else median
    near = torch.isfinite(disparity) & ((disparity - centre).abs() <= band)
    if surface == "median only":
        new = median
    else:
        weights = neighbourhood(torch.where(torch.isfinite(disparity), weight, 0.0), size)
        new, total = weighted_mean(w, weights, (w - centre[..., None]).abs() <= band)
        near &= total > 0
    if skip is not None:
        near &= ~skip
    return torch.where(near, new, disparity)


VARIANTS = {  # name -> (weight: "strength", "confidence" or "ones"; variant's keywords)
    "band 0.25 px": ("strength", {"band": 0.25}),
    "band 1 px": ("strength", {"band": 1.0}),
    "3x3": ("strength", {"size": 3}),
    "no weights": ("ones", {}),
    "confidence weights": ("confidence", {}),
    "surface from the median": ("strength", {"surface": "median"}),
    "two-depth tiles skipped": ("strength", {"skip": "two_depth"}),
    "3x3 median (§10)": ("strength", {"surface": "median only", "size": 3}),
}


def _methods(engine_result, nets: list[torch.Tensor], between: list[torch.Tensor]) -> dict:
    """Every scored estimate of one scene ``(ty, tx)`` (torch, NaN where the engine measured nothing)."""
    measured = torch.isfinite(engine_result.disparity)
    strength = engine_result.strength
    nan = torch.tensor(float("nan"))
    out = {"engine": engine_result.disparity, "engine + shipped step": context_step(engine_result.disparity, strength)}
    for n, net in enumerate(nets, start=1):
        net = torch.where(measured, net, nan)
        out[f"TPNET, {n} pass{'es' if n > 1 else ''}"] = net
        out[f"{SHIPPED}, {n} pass{'es' if n > 1 else ''}"] = context_step(net, strength)
        for name, (weight, kw) in VARIANTS.items():
            w = {"strength": strength, "confidence": engine_result.confidence,
                 "ones": torch.ones_like(strength)}[weight]
            kw = {**kw, "skip": two_depth(net)} if "skip" in kw else kw
            out[f"TPNET + {name}, {n} pass{'es' if n > 1 else ''}"] = variant(net, w, **kw)
    second = torch.where(measured, between[0], nan)
    out["TPNET, step between passes, 2 passes"] = second
    out["TPNET, step between passes and after, 2 passes"] = context_step(second, strength)
    return out


def _score(scenes: list[dict], name: str) -> dict:
    """Pooled statistics of method ``name`` over ``scenes`` per class, with the strict gross count."""
    out = {}
    for c in CLASSES:
        parts = [(s["methods"][name][s["classes"][c]], s["gt"][s["classes"][c]], s["surfaces"][s["classes"][c]],
                  s["engine_right"][s["classes"][c]]) for s in scenes]
        est, gt, surfaces, right = (np.concatenate([p[i] for p in parts]) for i in range(4))
        stats = error_stats(est, gt, np.ones(est.shape, bool), common=right, surfaces=surfaces)
        stats["gross_tiles"] = int(is_gross(est, gt).sum())
        out[c] = stats
    return out


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--scenes", type=int, default=32)
    parser.add_argument("--check-from", type=int, default=16, help="first check scene (before it: tuning scenes)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--seed", type=int, default=20000, help="first scene seed (not the held-out 10000+)")
    parser.add_argument("--weights", default=None, help="TPNET weights (default: the shipped ones)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default="out/bench_network_context.json", help="report path ('' to skip)")
    args = parser.parse_args(argv)
    if not 1 <= args.check_from < args.scenes:
        parser.error(f"--check-from: expected 1 .. --scenes - 1 (at least one tuning and one check scene), "
                     f"got {args.check_from} with --scenes {args.scenes}")

    rig = Rig(width=args.width, height=args.height)
    model = infer.load(args.weights, device=args.device)
    engine = DisparityEngine(rig.height, rig.width, rig=rig, device=args.device)
    tp = engine.tp
    layers = NetworkLayers(rig.offsets, tp.pairs, tp.torch_device)
    if infer.correlation(args.weights).resolved(tp.colours) != tp.config:
        tp = TileProcessor(rig.height, rig.width, config=infer.correlation(args.weights), device=args.device)

    def one_pass(target: torch.Tensor) -> torch.Tensor:
        return infer.infer(model, layers.of(engine.measure_at(tp, target)), target, grid=engine.grid)

    scenes = []
    for index in range(args.scenes):
        rendered = render(random_scene(rig, np.random.default_rng([args.seed, index])), rig, sensor=Sensor(),
                          supersample=2, seed=args.seed + index)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        result = engine.run(frames)
        if tp is not engine.tp:
            tp.load(engine.normalise(frames))
        measured = torch.isfinite(result.disparity)
        first = one_pass(torch.where(measured, result.disparity, result.search))
        nets = [first, one_pass(first)]
        stepped = context_step(torch.where(measured, first, torch.tensor(float("nan"))), result.strength)
        between = [one_pass(torch.where(measured, stepped, first))]
        gt = rendered.tile_disparity.astype(np.float64)
        engine_disparity = result.disparity.cpu().numpy().astype(np.float64)
        scenes.append({"gt": gt, "surfaces": rendered.tile_surfaces,
                       "classes": tile_classes(gt, rendered.tile_confidence, rendered.tile_spread),
                       "engine_right": reference_inliers(engine_disparity, gt),
                       "methods": {k: v.cpu().numpy().astype(np.float64)
                                   for k, v in _methods(result, nets, between).items()}})
        log(f"scene {index}: {int(measured.sum())} tiles measured")

    names = list(scenes[0]["methods"])
    subsets = {"tuning": scenes[: args.check_from], "check": scenes[args.check_from:]}
    stats = {subset: {name: _score(chosen, name) for name in names} for subset, chosen in subsets.items()}
    lines = []
    for subset, per in stats.items():
        first, last = (0, args.check_from - 1) if subset == "tuning" else (args.check_from, args.scenes - 1)
        lines.append(f"TPNET's context step, {subset} scenes {first}-{last} of seed {args.seed} ({args.width}x"
                     f"{args.height}), weights {args.weights or infer.DEFAULT_WEIGHTS.name}: own-inlier RMSE px "
                     f"(x the engine's), strict gross tiles, either-surface gross, tiles the engine has right made "
                     f"gross")
        engine_rmse = per["engine"]
        lines += common.format_table(["method", *CLASSES], [[name, *(
            f"{per[name][c]['rmse_inliers']:.4f} ({per[name][c]['rmse_inliers'] / engine_rmse[c]['rmse_inliers']:.3f}x)"
            f" {per[name][c]['gross_tiles']} {100 * per[name][c]['gross_either']:.2f}% {per[name][c]['new_gross']}"
            for c in CLASSES)] for name in names])
    print("\n".join(lines))
    report = {"bench": "network_context", "scenes": args.scenes, "check_from": args.check_from, "width": args.width,
              "height": args.height, "seed": args.seed, "machine": platform.platform(), "stats": stats, "table": lines}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
