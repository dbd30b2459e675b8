"""What limits TPNET's accuracy: its error against the precision of its start, over passes, and where it comes from.

    tpnet bench network_limits [--scenes 4] [--width 640 --height 480] [--seed 20000] [--weights PATH] [--json ...]
    python -m tpnet_gpu.bench.accuracy.bench_network_limits [same options]

Scenes are rendered with seeds no training scene and no held-out bench scene uses (``--seed`` 20000+), so this
analysis can be repeated without looking at the held-out scenes. Scored on the tiles the disparity engine
measures within 1 px of the ground truth (its inliers), per class (tpnet_gpu/evaluation.py):

* **start precision**: the network reads layers measured at ``gt + f (engine - gt)`` for f in ``FRACTIONS``
  (f = 1: the engine's own start; f = 0: the truth) and at ``gt`` + Gaussian noise of ``NOISE_PX``; RMSE of
  the start and of one network pass, and their ratio;
* **passes**: RMSE after 1..``--passes`` passes from the engine's start and from the truth (each pass
  re-measured at the previous pass's output): a network that converges keeps or lowers it;
* **sensor noise**: the same scenes rendered again without photon and read noise: engine and one network pass
  on each, scored on the tiles both engines get within 1 px - what is left without noise is the measurement's
  own bias (window, texture, sampling), which more precise starts cannot remove;
* **error budget**: flat tiles from the engine's start, binned by the layers' peak (the mean over the 4
  layers of each layer's maximum, a strength measure) and by disparity: each bin's share of the tiles, its
  engine and network RMSE, and its share of the network's squared error.
"""

from __future__ import annotations

import platform
import sys

import numpy as np
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity import DisparityEngine
from tpnet_gpu.evaluation import tile_classes
from tpnet_gpu.net import infer
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Sensor, random_scene, render

from tpnet_gpu.bench import common

log = common.logger("bench_network_limits")

FRACTIONS = (1.0, 0.5, 0.25, 0.1, 0.0)  # start = gt + f (engine - gt)
NOISE_PX = (0.1, 0.2)  # start = gt + N(0, sigma)
PEAK_BINS = (0.0, 0.1, 0.2, 0.3, 0.5, np.inf)
DISPARITY_BINS = (0.0, 2.0, 5.0, 10.0, 20.0, 40.0, np.inf)
CLASSES = ("flat", "edge", "all")


def _rmse(e: np.ndarray) -> float | None:
    """RMSE, None for no tiles (JSON null, '-' in the table)."""
    return float(np.sqrt(np.mean(e**2))) if e.size else None


def _f(x: float | None, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _budget(errors: np.ndarray, key: np.ndarray, bins) -> list[dict]:
    """Rows per bin of ``key``: share of tiles, engine / network RMSE, share of the network's squared error.
    ``errors`` (2, n): engine, network."""
    total = float(np.sum(errors[1] ** 2)) or 1.0
    rows = []
    for low, high in zip(bins[:-1], bins[1:]):
        sel = (key >= low) & (key < high)
        if not sel.any():
            continue
        rows.append({"low": low, "high": high, "share": float(sel.mean()),
                     "rmse_engine": _rmse(errors[0, sel]), "rmse_network": _rmse(errors[1, sel]),
                     "sse_share": float(np.sum(errors[1, sel] ** 2)) / total})
    return rows


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--scenes", type=int, default=4)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--seed", type=int, default=20000, help="first scene seed (not the held-out 10000+)")
    parser.add_argument("--weights", default=None, help="TPNET weights (default: the shipped ones)")
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--device", default=None)
    parser.add_argument("--json", default="out/bench_network_limits.json", help="report path ('' to skip)")
    args = parser.parse_args(argv)
    if args.scenes < 1 or args.passes < 1:
        parser.error("--scenes, --passes: expected at least 1")

    rig = Rig(width=args.width, height=args.height)
    model = infer.load(args.weights, device=args.device)
    engine = DisparityEngine(rig.height, rig.width, rig=rig, device=args.device)
    tp = engine.tp
    if infer.correlation(args.weights).resolved(tp.colours) != tp.config:
        tp = TileProcessor(rig.height, rig.width, config=infer.correlation(args.weights), device=args.device)

    starts = [f"gt + {f:g} (engine - gt)" for f in FRACTIONS] + [f"gt + N(0, {s:g} px)" for s in NOISE_PX]
    errors = {name: {c: [] for c in CLASSES} for name in starts}  # (start, net) error pairs per class
    chains = {"engine": {c: [] for c in CLASSES}, "gt": {c: [] for c in CLASSES}}  # errors over passes
    flat_rows = []  # (engine err, net err, peak, disparity) of flat tiles from the engine's start
    noise_pairs = {c: [] for c in CLASSES}  # (engine, net) errors with noise, then without
    for index in range(args.scenes):
        rng = np.random.default_rng([args.seed, index])
        scene = random_scene(rig, rng)
        rendered = render(scene, rig, sensor=Sensor(), supersample=2, seed=args.seed + index)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        gt = rendered.tile_disparity.astype(np.float64)
        found = engine.run(frames).disparity.cpu().numpy().astype(np.float64)
        if tp is not engine.tp:
            tp.load(engine.normalise(frames))
        inliers = np.isfinite(found) & (np.abs(found - gt) <= 1.0)
        classes = {c: m & inliers for c, m in tile_classes(gt, rendered.tile_confidence, rendered.tile_spread).items()}

        def one_pass(start: np.ndarray):
            target = torch.from_numpy(np.where(inliers, start, gt).astype(np.float32)).to(engine.device)
            layers = engine.measure_at(tp, target).layers
            return infer.infer(model, layers, target, grid=gt.shape).cpu().numpy().astype(np.float64), layers

        noise = {s: rng.normal(0.0, s, gt.shape) for s in NOISE_PX}
        for name, start in zip(starts, [gt + f * (found - gt) for f in FRACTIONS] + [gt + noise[s] for s in NOISE_PX]):
            net, layers = one_pass(start)
            for c in CLASSES:
                errors[name][c].append(np.stack([(start - gt)[classes[c]], (net - gt)[classes[c]]]))
            if name == starts[0]:  # the engine's own start: kept for the noise rows and the passes
                net_engine = net
                peak = layers.amax(dim=(-2, -1)).mean(dim=-1).cpu().numpy().reshape(gt.shape)
                sel = classes["flat"]
                flat_rows.append(np.stack([(found - gt)[sel], (net - gt)[sel], peak[sel], gt[sel]]))
        clean = render(scene, rig, sensor=Sensor(), supersample=2, seed=args.seed + index, noise=False)
        clean_frames = clean.raws.astype(np.float32) - clean.sensor.black_level
        found_clean = engine.run(clean_frames).disparity.cpu().numpy().astype(np.float64)
        if tp is not engine.tp:
            tp.load(engine.normalise(clean_frames))
        net_clean = one_pass(np.where(np.isfinite(found_clean), found_clean, gt))[0]
        both = inliers & np.isfinite(found_clean) & (np.abs(found_clean - gt) <= 1.0)
        tp.load(engine.normalise(frames))  # the noisy frames again, for the passes below
        for c in CLASSES:
            sel = classes[c] & both
            noise_pairs[c].append(np.stack([(e - gt)[sel] for e in (found, net_engine, found_clean, net_clean)]))
        for chain, estimates in (("engine", [found, net_engine]), ("gt", [gt])):
            while len(estimates) <= args.passes:
                estimates.append(one_pass(estimates[-1])[0])
            for c in CLASSES:
                chains[chain][c].append(np.stack([(e - gt)[classes[c]] for e in estimates]))
        log(f"scene {index}: {int(inliers.sum())} engine inliers")

    start_rows = {}
    for name, per in errors.items():
        start_rows[name] = {}
        for c, pairs in per.items():
            e = np.concatenate(pairs, axis=1)
            engine_rmse = _rmse(np.concatenate(errors[starts[0]][c], axis=1)[0])  # the same tiles for every start
            start_rows[name][c] = {"tiles": int(e.shape[1]), "rmse_start": _rmse(e[0]), "rmse_network": _rmse(e[1]),
                                   "ratio_to_engine": None if not engine_rmse or e.size == 0 else _rmse(e[1]) / engine_rmse}
    pass_rows = {chain: {c: [_rmse(x) for x in np.concatenate(v, axis=1)] for c, v in per.items()}
                 for chain, per in chains.items()}
    noise_rows = {c: [_rmse(x) for x in np.concatenate(v, axis=1)] for c, v in noise_pairs.items()}
    flat = np.concatenate(flat_rows, axis=1)
    budget = {"peak": _budget(flat[:2], flat[2], PEAK_BINS), "disparity": _budget(flat[:2], flat[3], DISPARITY_BINS)}

    lines = [f"TPNET limits, {args.scenes} rendered scenes of {args.width}x{args.height} (seeds {args.seed}+), "
             f"weights {args.weights or infer.DEFAULT_WEIGHTS.name}; RMSE on the engine's inliers, ratio to the engine"]
    lines += common.format_table(["start", *(f"{c} start / net (x engine)" for c in CLASSES)],
                                 [[name, *(f"{_f(start_rows[name][c]['rmse_start'])} / {_f(start_rows[name][c]['rmse_network'])} "
                                           f"({_f(start_rows[name][c]['ratio_to_engine'], 2)}x)" for c in CLASSES)]
                                  for name in starts])
    lines += common.format_table(["passes from", *(f"{c}: start, 1..{args.passes}" for c in CLASSES)],
                                 [[chain, *(" ".join(_f(x) for x in pass_rows[chain][c]) for c in CLASSES)]
                                  for chain in chains])
    lines += common.format_table(["class (tiles both engines get)", "engine", "net", "engine, no noise", "net, no noise"],
                                 [[c, *(_f(x) for x in noise_rows[c])] for c in CLASSES])
    for key, rows in budget.items():
        lines += common.format_table([f"flat, {key} bin", "tiles", "engine rmse", "net rmse", "share of net SSE"],
                                     [[f"[{r['low']:g}, {r['high']:g})", f"{100 * r['share']:.0f} %", _f(r["rmse_engine"]),
                                       _f(r["rmse_network"]), f"{100 * r['sse_share']:.0f} %"] for r in rows])
    print("\n".join(lines))
    report = {"bench": "network_limits", "scenes": args.scenes, "width": args.width, "height": args.height,
              "seed": args.seed, "passes": args.passes, "machine": platform.platform(), "starts": start_rows,
              "passes_rmse": pass_rows, "noise_free": noise_rows, "budget": budget, "table": lines}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
