"""The disparity engine and TPNET against the old sweep + LMA loop on held-out rendered scenes.

    tpnet bench network [--scenes 4] [--width 640 --height 480] [--passes 3] [--weights PATH] [--rig FILE]
                        [--mono] [--json ...] [--png ...]
    python -m tpnet_gpu.bench.accuracy.bench_network [same options]

Scenes are rendered fresh with seeds no training scene uses (``--seed`` 10000+), the demo scene first. Methods:
the old loop (8-step sweep, LMA refinement, consistency pass: ``tpnet_gpu.baseline.estimate``, the reference),
the disparity engine (``tpnet_gpu.disparity``) with its default on-device measurement and with the quad's LMA,
and TPNET reading the layers at the engine's disparities (its first-stage answer where it measured none), each
further pass re-correlating at the previous pass's disparity (one row per pass count, up to ``--passes``), then its
context step as the pipeline runs it (``net/context.py``; a row "no context" per pass count without it).
Scored per class (tpnet_gpu/evaluation.py): strict and either-surface gross, own-inlier RMSE, rmse-ref on the
tiles the old loop gets within 1 px (the paper's protocol), tiles made gross that it had right, coverage,
confidence ranking, tile-processor passes and seconds per frame (the engine timed warm).
``--rig FILE`` (a rig file or a shipped one, at the bench's size when ideal) renders the scenes with that rig; a rig
other than the quad has no old loop (quad only): its methods are the engine (and the engine with the LMA where its
pairs lie along quad pairs, ``disparity.measure.lma_slots``: the binocular rig) and TPNET with the weights trained
for its layer lags (default: the shipped ones), scored against the engine. ``--mono``: mono cameras (grey frames,
no old loop) and weights trained on them. Table + JSON + PNG (the PNG needs matplotlib, of the optional ``bench``
extra).
"""

from __future__ import annotations

import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from tpnet_gpu.baseline.estimate import BASELINE_CORRELATION, estimate, processor_correlator
from tpnet_gpu.io import rigfile
from tpnet_gpu.camera import Rig
from tpnet_gpu.config import EngineConfig
from tpnet_gpu.disparity import DisparityEngine
from tpnet_gpu.disparity.measure import lma_slots
from tpnet_gpu.disparity.pairs import default_pairs, pair_vectors
from tpnet_gpu.net import infer
from tpnet_gpu.net.context import context_step
from tpnet_gpu.net.layers import QUAD_LAGS, NetworkLayers, lags_match, rig_lags
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Sensor, render

from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import report as report_tools

log = common.logger("bench_network")


OLD = "old sweep + LMA"  # tpnet_gpu.baseline.estimate: the 8-step sweep, refinement and consistency pass
ENGINE = "engine"  # tpnet_gpu.disparity with its default measurement (the pairs' axis peak, on the device)
ENGINES = {ENGINE: "axis", "engine (LMA)": "lma"}


class CountingCorrelator:
    """A ``Correlator`` that counts its calls (each is one full tile-processor pass)."""

    def __init__(self, correlate):
        self.correlate, self.calls = correlate, 0

    def __call__(self, target):
        self.calls += 1
        return self.correlate(target)


def pass_name(n: int, context: bool = True) -> str:
    return f"TPNET ({n} pass{'es' if n > 1 else ''}{'' if context else ', no context'})"


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    report_tools.scene_arguments(parser, "network", scenes=4, width=640, height=480, seed=10000)
    parser.add_argument("--weights", default=None, help="TPNET weights (default: the shipped ones)")
    parser.add_argument("--passes", type=int, default=3, help="most network passes (re-measured at its own output)")
    parser.add_argument("--rig", default=None, help="rig file or shipped rig name (default: the quad)")
    parser.add_argument("--mono", action="store_true", help="mono cameras (grey frames; the weights must be mono)")
    args = parser.parse_args(argv)
    cfa = None if args.mono else Sensor().cfa
    if args.scenes < 1 or args.passes < 1:
        parser.error("--scenes, --passes: expected at least 1")
    if args.png:
        common.require_extras("matplotlib")

    rig = Rig(width=args.width, height=args.height)
    if args.rig is not None:
        rig = rigfile.load(args.rig)
        rig = replace(rig, width=args.width, height=args.height, _cache={}) if rig.is_ideal() else rig
    quad = lags_match(rig_lags(rig.offsets), QUAD_LAGS) and cfa is not None  # the old loop reads Bayer frames
    # the old loop is the quad's only; the LMA also takes rigs whose pairs lie along quad pairs (binocular)
    lma = quad or lma_slots(pair_vectors(rig.offsets, default_pairs(rig.offsets))) is not None
    engine_names = ENGINES if lma else {ENGINE: "axis"}
    colours = 1 if cfa is None else 3
    weights = args.weights if args.weights is not None else infer.shipped_for(rig_lags(rig.offsets), colours)
    if weights is None:
        parser.error(f"--weights: no shipped TPNET weights for this rig (layer lags {rig_lags(rig.offsets)}) and "
                     f"{colours}-colour frames")
    if not infer.fits_colours(weights, colours):
        parser.error(f"--weights: {weights} were not trained on {colours}-colour frames (--mono: mono)")
    if not lags_match(infer.lags(weights), rig_lags(rig.offsets)):
        parser.error(f"--weights: {weights} were trained for layer lags {infer.lags(weights)}, the rig's are "
                     f"{rig_lags(rig.offsets)}")
    model = infer.load(weights, device=args.device)
    base_tp = TileProcessor(rig.height, rig.width, config=BASELINE_CORRELATION, device=args.device) if quad else None
    engines = {name: DisparityEngine(rig.height, rig.width, rig=rig, cfa=cfa, config=EngineConfig(measure=measure),
                                     device=args.device) for name, measure in engine_names.items()}
    network_tp = engines[ENGINE].tp
    layers = NetworkLayers(rig.offsets, network_tp.pairs, network_tp.torch_device)
    if infer.correlation(weights).resolved(network_tp.colours) != network_tp.config:
        network_tp = TileProcessor(rig.height, rig.width, camera_offsets=rig.offsets_array(), pairs=network_tp.pairs,
                                   cfa=cfa, config=infer.correlation(weights), device=args.device)
    scenes = []
    for index in range(args.scenes):
        scene = report_tools.bench_scene(rig, args.seed, index)
        rendered = render(scene, rig, sensor=Sensor(cfa=cfa), supersample=2, seed=args.seed + index)
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        shape = rendered.tile_disparity.shape
        estimates, confidences, costs, results = {}, {}, {}, {}
        if quad:
            start = time.perf_counter()
            counted = CountingCorrelator(processor_correlator(base_tp, frames))
            old = estimate(counted, shape)
            estimates[OLD], confidences[OLD] = old.disparity, old.strength
            costs[OLD] = {"seconds": time.perf_counter() - start, "tile_passes": float(counted.calls)}
        for name, engine in engines.items():
            engine.run(frames)  # warm-up of this size (kernels, tables) outside the timing
            start = time.perf_counter()
            result = results[name] = engine.run(frames)
            estimates[name] = result.disparity.cpu().numpy().astype(np.float64)
            confidences[name] = result.confidence.cpu().numpy().astype(np.float64)
            costs[name] = {"seconds": time.perf_counter() - start, "tile_passes": result.tile_passes}
        # TPNET reads the layers at the engine's disparities (its first stage's answer where it measured none)
        result = results[ENGINE]  # the pipeline's engine (the loop above ended with the LMA one)
        measured = torch.isfinite(result.disparity)
        target = torch.where(measured, result.disparity, result.search)
        if network_tp is not engines[ENGINE].tp:
            network_tp.load(engines[ENGINE].normalise(frames))
        start = time.perf_counter()
        for n in range(1, args.passes + 1):
            target = infer.infer(model, layers.of(engines[ENGINE].measure_at(network_tp, target)), target, grid=shape)
            net = torch.where(measured, target, torch.full_like(target, float("nan")))  # the engine's tiles
            raw_seconds = time.perf_counter() - start
            # the pipeline's answer: the context step after the last pass (the next pass reads the raw output)
            stepped = context_step(net, result.strength)
            for name, disparity, seconds in ((pass_name(n, context=False), net, raw_seconds),
                                             (pass_name(n), stepped, time.perf_counter() - start)):
                estimates[name] = disparity.cpu().numpy().astype(np.float64)
                costs[name] = {"seconds": costs[ENGINE]["seconds"] + seconds,
                               "tile_passes": costs[ENGINE]["tile_passes"] + n}
        log(f"scene {index} ({scene.name}): " + ", ".join(f"{k} {v['seconds']:.2f} s" for k, v in costs.items()))
        scenes.append({"gt": rendered.tile_disparity, "confidence": rendered.tile_confidence,
                       "spread": rendered.tile_spread, "estimates": estimates, "surfaces": rendered.tile_surfaces,
                       "confidences": confidences, "per_frame": costs})

    methods = ([OLD] if quad else []) + [*engine_names] + [name for n in range(1, args.passes + 1)
                                                           for name in (pass_name(n, context=False), pass_name(n))]
    rig_text = ("" if args.rig is None else f", rig {args.rig} ({rig.cams} cameras)") + (", mono" if args.mono else "")
    title = (f"{'Old sweep, the' if quad else 'The'} disparity engine and TPNET, {args.scenes} held-out rendered scenes "
             f"of {args.width}x{args.height} (seeds {args.seed}+){rig_text}, weights "
             f"{Path(weights or infer.DEFAULT_WEIGHTS).name}")
    meta = {"bench": "network", "scenes": args.scenes, "width": args.width, "height": args.height,
            "seed": args.seed, "passes": args.passes, "rig": args.rig, "mono": args.mono,
            "machine": platform.platform()}
    return report_tools.publish(scenes, methods, title, OLD if quad else ENGINE, meta, args.json, args.png, log=log)


if __name__ == "__main__":
    sys.exit(common.run(main))
