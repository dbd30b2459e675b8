"""Throughput benchmark: the tile processor and TPNET per stage and per whole quad frame.

    tpnet bench throughput [--device cpu|cuda] [--height 1936 --width 2592] [--repeat 3] [--threads N]
                           [--taichi-threads 1,2 | --no-taichi] [--json out/bench_throughput.json] [--soak N]
                           [--pipeline-sizes 640x480,2592x1936] [--pipeline-frames 3] [--pipeline-only]
    python -m tpnet_gpu.bench.throughput.bench_throughput [same options]

One quad frame (4 cameras, random 12-bit raw values, seeded), every tile at one target disparity. Three
implementations of the same tile-processor math, run one after the other (each one's outputs are freed before
the next starts: a full-frame CLT is ~1 GB):

* **warp**: ``TileProcessor`` (the Warp kernels), then TPNET (``tpnet_gpu.net.model.TPNet``) on its layers;
* **numpy**: the vectorised float32 NumPy twin (bench/twins/numpy_tp.py), CPU runs only;
* **torch**: the plain-PyTorch-ops twin (bench/twins/torch_tp.py) on the processor's torch device;
* **taichi**: ``TileProcessor(backend="taichi")`` (kernels/taichi_*.py, the same buffers and outputs), then the
  same network. Taichi fixes its CPU thread count at ``ti.init``, so each count of ``--taichi-threads`` (default
  1 and 2) runs in its own process (``TPNET_TAICHI_THREADS``); on CUDA one process runs it on the GPU. Its
  outputs are compared with a Warp processor's on the same frame in that process.

Rows: convert, correlate, texture (Warp and Taichi), network stage 1 (tile inputs + the per-tile MLP), network stage 2
(5x5 cluster convolution + the rest), network whole frame (``forward_frame``), TP whole frame (prepare + convert +
correlate for Warp; convert + correlate for the twins, which take the processor's tile centres), TP fused whole
frame (Warp and Taichi: prepare + ``TileProcessor.fused``, the one-pass path ``measure`` takes when the CLT tiles
are not kept; timed on the same processor, so its peak memory is not the fused one's) and TP+network
whole frame (the TP whole frame, then the network on its layers; the twins combine their correlations into layers
with ``torch_layers``). The network rows are one PyTorch model on the processor's device, timed once and listed
under warp. Each row: one warm-up call (Warp: kernel compilation or cache load; all: first touch of buffers), then
``--repeat`` back-to-back calls give median and best (the steady state of a stream of frames). Timers stop after
``wp.synchronize_device`` / ``torch.cuda.synchronize``.

On CUDA: absolute ms and frames/s, Warp vs plain PyTorch ops, the CUDA-graph replay gain when ``TileProcessor``
offers a graph option (``graph`` / ``use_graph``; 'n/a' otherwise; on CPU the same option records a Warp CPU
graph, measured too), and the paper's GTX 1050 Ti figures beside ours. Targets: on an
H100 the TP <= 1 ms and TP+network <= 3 ms per quad frame; on CPU the Warp path >= 2x the vectorised NumPy one.

Pipeline rows (throughput_pipeline.py): ``Pipeline.process`` per whole frame and per stage (engine search,
engine refine, network, texture) for each of ``--pipeline-sizes`` (default 640x480; add 2592x1936 for the full
frame), one full-frame tile-processor pass beside the torch twin's on the same device, the paper's figures as a
reference row and the frame's H200 floor. ``--pipeline-only`` runs just those. Floor (throughput_floor.py): bytes
and FLOPs counted from the buffer and transform sizes, at the H200's HBM bandwidth and FP32 peak, for the
whole-frame rows and the pipeline frames.

``--soak N`` first streams N random frames of ``--height`` x ``--width`` (fresh frames and per-tile target
disparities each time) through ``TileProcessor.process`` and ``TPNet.forward_frame``, sampling the process RSS
(VmRSS) every 50 frames. Table, paper figures, targets and soak summary go to stdout, progress to stderr, all
numbers with machine information to JSON.

Modules: this one (the Warp and twin runs, the network split, ``main``); throughput_common.py (stage timing,
agreement), throughput_taichi.py (the Taichi worker processes), throughput_stream.py (graph replay,
soak), throughput_report.py (table, targets, printed report), throughput_pipeline.py (the pipeline rows),
throughput_floor.py (bytes, FLOPs and the H200 floor).
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.net import frame as net_frame
from tpnet_gpu.net import functional as net_functional
from tpnet_gpu.net import model as net_model
from tpnet_gpu.processor import BACKENDS, TileProcessor
from tpnet_gpu.runtime.warp_setup import default_device, init_warp

from tpnet_gpu.bench import common
from tpnet_gpu.bench.common import PAPER_GPU, PAPER_TP_MS
from tpnet_gpu.bench.throughput.throughput_common import AGREEMENT_TOL, agreement, log, run_stages
from tpnet_gpu.bench.throughput.throughput_floor import H200, tp_rows_floor
from tpnet_gpu.bench.throughput.throughput_pipeline import SCENES, parse_sizes, print_pipeline
from tpnet_gpu.bench.throughput.throughput_pipeline import run_all as pipeline_rows
from tpnet_gpu.bench.throughput.throughput_report import PAPER_NETWORK_S, print_report, stage_table, targets
from tpnet_gpu.bench.throughput.throughput_stream import measure_graph_replay, soak
from tpnet_gpu.bench.throughput.throughput_taichi import run_taichi, spawn_taichi, taichi_columns
from tpnet_gpu.bench.twins.numpy_tp import numpy_convert, numpy_correlate
from tpnet_gpu.bench.twins.torch_tp import torch_convert, torch_correlate, torch_layers

IMPLEMENTATIONS = ("warp", "numpy", "torch")


# --- network stages ---------------------------------------------------------------------------------------------
def _params(net: net_model.TPNet):
    return [(m.weight, m.bias) for m in net.stage1], [(m.weight, m.bias) for m in net.stage2]


def network_stage1(net: net_model.TPNet, layers: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Stage-1 features ``(ty, tx, F)``: tile inputs (layers + target, NaN -> 0) through the per-tile MLP."""
    return net_functional.stage1_features(net_functional.tile_inputs(layers, target), _params(net)[0])


def network_stage2(net: net_model.TPNet, features: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Residuals ``(ty, tx)`` from stage-1 features: the second half of ``frame.frame_residual`` (clone 0, all tiles
    active), by the model's own ``frame_stage2``."""
    return net_frame.frame_stage2(features, target, _params(net)[1], (0,))[..., 0]


# --- the three implementations ----------------------------------------------------------------------------------
def run_warp(args, cfa, device, frames_t, target, net) -> dict:
    """Warp processor stages and the network on its layers. Returns warm-up and run timings, copies of the outputs
    the twins are compared with, and set-up facts; the processor itself is freed on return."""
    tdev = target.device
    start = time.perf_counter()
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, clt=True, device=str(device), backend="warp")
    setup_ms = 1e3 * (time.perf_counter() - start)
    if tp.pairs != tables.QUAD_PAIRS:
        raise SystemExit("the network needs the quad's 6 pairs (network layers)")

    def sync() -> None:
        wp.synchronize_device(device)
        if tdev.type == "cuda":
            torch.cuda.synchronize(tdev)

    start = time.perf_counter()
    result = tp.process(frames_t, args.disparity)  # compiles or loads the kernels; its views stay valid
    sync()
    first_process_ms = 1e3 * (time.perf_counter() - start)
    layers = result.layers.view(tp.tiles_y, tp.tiles_x, 4, 9, 9)
    state = {}

    def tp_whole() -> None:
        tp.prepare(frames_t, args.disparity)
        tp.convert()
        tp.correlate()

    def tp_fused() -> None:
        tp.prepare(frames_t, args.disparity)
        tp.fused()

    def stage1() -> None:
        state["features"] = network_stage1(net, layers, target)

    def stage2() -> None:
        state["residual"] = network_stage2(net, state["features"], target)

    def network() -> None:
        state["residual"] = net.forward_frame(layers, target)

    def tp_network() -> None:
        tp_whole()
        network()

    stages = {
        "convert": tp.convert,
        "correlate": tp.correlate,
        "texture": tp.texture,
        "network stage 1": stage1,
        "network stage 2": stage2,
        "network whole frame": network,
        "TP whole frame": tp_whole,
        "TP fused whole frame": tp_fused,
        "TP+network whole frame": tp_network,
    }
    with torch.inference_mode():
        warmup, runs = run_stages("warp", stages, sync, args.repeat)
        # The timed network split is the same computation as forward_frame: checked on this frame.
        split = network_stage2(net, network_stage1(net, layers, target), target)
        split_diff = float((split - net.forward_frame(layers, target)).abs().max())
    outputs = {name: getattr(result, name).clone() for name in ("clt", "corr", "layers", "centres")}
    return {"warmup": warmup, "runs": runs, "outputs": {**outputs, "split_diff": split_diff, "config": tp.config,
                                                         "setup": {"warp_setup_ms": setup_ms,
                                                                   "warp_first_process_ms": first_process_ms}}}


def run_twin(impl: str, args, cfa, frames, frames_t, target, net, reference: dict) -> tuple[dict, dict, dict]:
    """The NumPy (host) or plain-PyTorch (processor's device) twin at the processor's tile centres; returns
    warm-up and run timings and the max relative differences to the processor's outputs. Outputs are freed on
    return."""
    cfg = reference["config"]
    pairs = tables.QUAD_PAIRS
    grid = (*target.shape, 4, 9, 9)
    state = {}
    if impl == "numpy":
        centres = reference["centres"].cpu().numpy()

        def convert() -> None:
            state["clt"] = None  # drop the previous output first: at full frame it is ~1 GB
            state["clt"] = numpy_convert(frames, centres, cfa)

        def correlate() -> None:
            state["corr"] = None
            state["corr"] = numpy_correlate(state["clt"], pairs, cfg.colour_weights, cfg.fat_zero, cfg.sigma_rb,
                                            cfg.sigma_corr)

        def layers() -> torch.Tensor:  # the twin has no layer combination: torch's, on the host arrays
            return torch_layers(torch.from_numpy(state["corr"]), cfg.net_offset)

        sync = None
    else:
        centres = reference["centres"]

        def convert() -> None:
            state["clt"] = None
            state["clt"] = torch_convert(frames_t, centres, cfa)

        def correlate() -> None:  # + the layer combination, as the processor's correlate stage
            state["corr"] = state["layers"] = None
            state["corr"] = torch_correlate(state["clt"], pairs, cfg.colour_weights, cfg.fat_zero, cfg.sigma_rb,
                                            cfg.sigma_corr)
            state["layers"] = torch_layers(state["corr"], cfg.net_offset)

        def layers() -> torch.Tensor:
            return state["layers"]

        def sync() -> None:
            if target.device.type == "cuda":
                torch.cuda.synchronize(target.device)

    def tp_whole() -> None:
        state["clt"] = state["corr"] = state["layers"] = None
        convert()
        correlate()

    def tp_network() -> None:
        tp_whole()
        state["residual"] = net.forward_frame(layers().view(grid), target)

    stages = {"convert": convert, "correlate": correlate, "TP whole frame": tp_whole,
              "TP+network whole frame": tp_network}
    with torch.inference_mode():
        warmup, runs = run_stages(impl, stages, sync, args.repeat)
    log(f"{impl}: comparing with warp ...")
    agree = {name: agreement(state[name] if name != "layers" else layers(), reference[name])
             for name in ("clt", "corr", "layers")}
    return warmup, runs, agree


# --- main -------------------------------------------------------------------------------------------------------
def _device_entry(device, tdev: torch.device) -> dict:
    return {"warp_device": str(device), "torch_device": str(tdev), "name": common.device_name(device),
            "is_cuda": device.is_cuda}


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__)
    common.frame_arguments(parser)
    parser.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: torch's own)")
    parser.add_argument("--soak", type=int, default=0, help="frames to stream for the RSS soak (default 0: none)")
    parser.add_argument("--json", default="out/bench_throughput.json", help="output JSON path ('' to skip)")
    parser.add_argument("--taichi-threads", default="1,2",
                        help="Taichi CPU thread counts, one process each (default 1,2; CPU runs only)")
    parser.add_argument("--no-taichi", action="store_true", help="skip the Taichi backend")
    parser.add_argument("--taichi-worker", default=None, help=argparse.SUPPRESS)  # internal: JSON path of a worker
    parser.add_argument("--pipeline-sizes", default="640x480",
                        help="Pipeline.process rows, WIDTHxHEIGHT,... (default 640x480; add 2592x1936: ~7 GB; '' none)")
    parser.add_argument("--pipeline-frames", type=int, default=3, help="timed pipeline frames per size (default 3)")
    parser.add_argument("--pipeline-scene", choices=SCENES, default="demo", help="pipeline frames (default demo)")
    parser.add_argument("--pipeline-backend", choices=BACKENDS, default=None,
                        help="the pipeline's kernel language (default: TileProcessor's default for the device)")
    parser.add_argument("--pipeline-only", action="store_true", help="only the pipeline rows (no tile-processor rows)")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    try:
        args.pipeline_sizes = parse_sizes(args.pipeline_sizes)
    except ValueError as exc:
        parser.error(str(exc))
    if args.pipeline_frames < 1:
        parser.error("--pipeline-frames: expected at least 1")
    try:
        args.taichi_threads = [int(n) for n in args.taichi_threads.split(",") if n.strip()]
    except ValueError:
        parser.error(f"--taichi-threads: expected comma-separated thread counts, got {args.taichi_threads!r}")
    if any(n < 1 for n in args.taichi_threads):
        parser.error(f"--taichi-threads: expected thread counts >= 1, got {args.taichi_threads}")
    cfa = common.frame_cfa(parser, args)
    if args.soak < 0:
        parser.error("--soak: expected a number of frames >= 0")
    if args.threads is not None:
        if args.threads < 1:
            parser.error("--threads: expected at least 1")
        torch.set_num_threads(args.threads)
    init_warp()
    device = wp.get_device(args.device or default_device())
    tdev = torch.device(wp.device_to_torch(device))
    is_cuda = device.is_cuda
    torch.manual_seed(args.seed)
    net = net_model.TPNet().eval().to(tdev)  # Xavier-initialised: the timing does not depend on the weights

    if args.pipeline_only:  # the pipeline rows alone
        report = {"pipeline": pipeline_rows(args, device, tdev), "device": _device_entry(device, tdev),
                  "machine": common.machine_info(torch_threads=torch.get_num_threads())}
        print_pipeline(report["pipeline"], report["device"]["name"])
        if args.json:
            log(f"wrote {common.save_json(report, args.json)}")
        return report
    soak_report = None
    if args.soak:
        log(f"soak: {args.soak} frames of {args.width}x{args.height} ...")
        soak_report = soak(args, cfa, device, net, args.soak)
        gc.collect()

    cams = len(tables.QUAD_OFFSETS)
    frames = common.random_frames(np.random.default_rng(args.seed), args.height, args.width, cams)
    frames_t = torch.from_numpy(frames).to(tdev)  # float32, contiguous: the processor reads it in place
    tiles_y, tiles_x = args.height // 8, args.width // 8
    target = torch.full((tiles_y, tiles_x), args.disparity, dtype=torch.float32, device=tdev)
    if args.taichi_worker:  # a Taichi worker process: only the Taichi rows, to a JSON file for the parent
        report = run_taichi(args, cfa, device, frames_t, target, net)
        Path(args.taichi_worker).write_text(json.dumps(report))
        return report
    log(f"{args.width}x{args.height}, {cams} cameras, {tiles_y * tiles_x} tiles on {device} "
        f"({common.device_name(device)}); torch threads {torch.get_num_threads()}")

    runs, warmups = {}, {}
    warp = run_warp(args, cfa, device, frames_t, target, net)
    warmups["warp"], runs["warp"] = warp["warmup"], warp["runs"]
    reference = warp["outputs"]
    del warp
    gc.collect()  # the processor and its buffers are gone; the outputs to compare with are kept
    agree = {}
    for impl in ("torch",) if is_cuda else ("numpy", "torch"):
        warmups[impl], runs[impl], agree[impl] = run_twin(impl, args, cfa, frames, frames_t, target, net,
                                                              reference)
        gc.collect()
    network_split_diff, setup = reference["split_diff"], reference["setup"]
    del reference
    gc.collect()
    columns = taichi_columns(args, is_cuda)
    taichi_setups = {}
    for column, threads in columns:
        log(f"{column}: in a fresh process ...")
        worker = spawn_taichi(argv, threads)
        warmups[column], runs[column], agree[column] = worker["warmup"], worker["runs"], worker["agreement"]
        taichi_setups[column] = worker["setup"]
    impls = IMPLEMENTATIONS + tuple(column for column, _ in columns)
    log("graph replay ...")
    graph = measure_graph_replay(args, cfa, device, frames_t, target, net)
    del frames, frames_t
    gc.collect()
    pipeline = pipeline_rows(args, device, tdev)

    # --- report ---------------------------------------------------------------------------------------------------
    table = stage_table(runs, warmups, impls)
    gpu_name = common.device_name(device)
    report_targets = targets(table, graph, gpu_name, is_cuda, (args.height, args.width))

    report = {
        "frame": common.frame_info(args, cfa, cams, tiles_y * tiles_x, len(tables.QUAD_PAIRS)),
        "timing": {
            "repeat": args.repeat, "statistic": "median (best and all runs listed)",
            "sync": "wp.synchronize_device / torch.cuda.synchronize before each timer stops",
            "per_row": "one warm-up call, then the timed calls back to back",
            "excluded": "each row's warm-up call; the processor's construction",
            "network": "one TPNet (Xavier init) on the processor's torch device in inference mode, fed the "
                       "processor's layers; listed under warp (the same model serves every path)",
            "twins": "numpy/torch take the processor's tile centres (no prepare stage); the torch correlate row "
                     "includes the layer combination (as the processor's correlate stage), the numpy one does not; "
                     "their TP+network rows feed torch_layers of their own correlations to the network",
            "taichi": "TileProcessor(backend='taichi') in a fresh process per column (taichi-Nt: N CPU threads, "
                      "TPNET_TAICHI_THREADS; taichi-cuda: the GPU); its warm-up includes loading the kernels from "
                      "Taichi's offline cache (or compiling them on a cold cache); agreement: corr and layers "
                      "against a Warp processor on the same frame",
            "taichi_setup": taichi_setups,
            **setup,
        },
        "stages": table,
        "columns": list(impls),
        "agreement": {**agree, "tolerance": f"elements_over_tol: |twin - warp| > {AGREEMENT_TOL:g} max |warp|",
                      "layers_note": "the pair combination of the layers is discontinuous at 0 (sqrt((a + o)(b + o))"
                                     " - o only where a > 0 and b > 0): pair values ~1e-8 whose sign differs by "
                                     "rounding give isolated large differences",
                      "network_split_vs_forward_frame_max_abs_diff": network_split_diff},
        "graph_replay": graph,
        "paper": {"gpu": PAPER_GPU, "tp_ms": PAPER_TP_MS, "network_s": list(PAPER_NETWORK_S),
                  "note": "one full quad frame; comparable only with CUDA timings"},
        "targets": report_targets,
        "floor": {"gpu": H200, "rows": tp_rows_floor(args.height, args.width, 1 if cfa is None else 3, net),
                  "counting": "bench/throughput/throughput_floor.py"},
        "pipeline": pipeline,
        "soak": soak_report,
        "device": _device_entry(device, tdev),
        "machine": common.machine_info(
            torch_threads=torch.get_num_threads(),
            threads="Warp CPU kernels run on one thread; NumPy's BLAS and torch use all cores unless limited "
                    "(--threads for torch)",
            cuda=torch.cuda.get_device_name(tdev) if tdev.type == "cuda" else None),
    }
    print_report(report)
    print_pipeline(pipeline, gpu_name)
    if args.json:
        log(f"wrote {common.save_json(report, args.json)}")
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
