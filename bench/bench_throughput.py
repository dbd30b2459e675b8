"""Throughput benchmark: the tile processor and TPNET per stage and per whole quad frame.

    python bench/bench_throughput.py [--device cpu|cuda] [--height 1936 --width 2592] [--repeat 3] [--threads N]
                                     [--taichi-threads 1,2 | --no-taichi] [--json out/bench_throughput.json]
                                     [--soak N]

One quad frame (4 cameras, random 12-bit raw values, seeded), every tile at one target disparity. Three
implementations of the same tile-processor math, run one after the other (each one's outputs are freed before
the next starts: a full-frame CLT is ~1 GB):

* **warp**: ``TileProcessor`` (the Warp kernels), then TPNET (``tpnet_gpu.net.model.TPNet``) on its layers;
* **numpy**: the vectorised float32 NumPy twin (bench/numpy_tp.py), CPU runs only;
* **torch**: the plain-PyTorch-ops twin (bench/torch_tp.py) on the processor's torch device;
* **taichi**: ``TileProcessor(backend="taichi")`` (kernels/taichi_*.py, the same buffers and outputs), then the
  same network. Taichi fixes its CPU thread count at ``ti.init``, so each count of ``--taichi-threads`` (default
  1 and 2) runs in its own process (``TPNET_TAICHI_THREADS``); on CUDA one process runs it on the GPU. Its
  outputs are compared with a Warp processor's on the same frame in that process.

Rows: convert, correlate, texture (Warp and Taichi), network stage 1 (tile inputs + the per-tile MLP), network stage 2
(5x5 cluster convolution + the rest), network whole frame (``forward_frame``), TP whole frame (prepare + convert +
correlate for Warp; convert + correlate for the twins, which take the processor's tile centres) and TP+network
whole frame (the TP whole frame, then the network on its layers; the twins combine their correlations into layers
with ``torch_layers``). The network rows are one PyTorch model on the processor's device, timed once and listed
under warp. Each row: one warm-up call (Warp: kernel compilation or cache load; all: first touch of buffers), then
``--repeat`` back-to-back calls give median and best (the steady state of a stream of frames). Timers stop after
``wp.synchronize_device`` / ``torch.cuda.synchronize``.

On CUDA: absolute ms and frames/s, Warp vs plain PyTorch ops, the CUDA-graph replay gain when ``TileProcessor``
offers a graph option (``graph`` / ``use_graph``; 'n/a' otherwise; on CPU the same option records a Warp CPU
graph, measured too), and the paper's GTX 1050 Ti figures beside ours. Targets: on an
H100 the TP <= 1 ms and TP+network <= 3 ms per quad frame; on CPU the Warp path >= 2x the vectorised NumPy one.

``--soak N`` first streams N random frames of ``--height`` x ``--width`` (fresh frames and per-tile target
disparities each time) through ``TileProcessor.process`` and ``TPNet.forward_frame``, sampling the process RSS
(VmRSS) every 50 frames. Table, paper figures, targets and soak summary go to stdout, progress to stderr, all
numbers with machine information to JSON.
"""

from __future__ import annotations

import argparse
import gc
import inspect
import os
import platform
import re
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tp import PAPER_GPU, PAPER_TP_MS, cpu_model, device_name, summary, timed_ms  # noqa: E402
from numpy_tp import numpy_convert, numpy_correlate  # noqa: E402
from torch_tp import torch_convert, torch_correlate, torch_layers  # noqa: E402
from report import save_json  # noqa: E402

from tpnet_gpu import tables  # noqa: E402
from tpnet_gpu.net import model as net_model  # noqa: E402
from tpnet_gpu.processor import TileProcessor  # noqa: E402
from tpnet_gpu.warp_setup import default_device, init_warp  # noqa: E402

# Filippov & Dzhimiev, "See far with TPNET", on a GTX 1050 Ti, one full quad frame (as quoted in the issue):
# the whole TP 87 ms; the network 0.46 + 0.12 s (listed here beside our stage 1 and stage 2).
PAPER_NETWORK_S = (0.46, 0.12)
TARGET_GPU = "H100"
TARGET_TP_MS = 1.0
TARGET_TP_NET_MS = 3.0
TARGET_CPU_RATIO = 2.0
SOAK_EVERY = 50  # frames between RSS samples

IMPLEMENTATIONS = ("warp", "numpy", "torch")


# Table rows: (name, whole frame?). Each implementation maps the names it runs to a callable ``fn()``.
ROWS = (
    ("convert", False),
    ("correlate", False),
    ("texture", False),  # Warp and Taichi only: no twin (the float64 reference is the oracle)
    ("network stage 1", False),  # the network rows: one PyTorch model, listed under warp
    ("network stage 2", False),
    ("network whole frame", True),
    ("TP whole frame", True),
    ("TP+network whole frame", True),
)
StageFns = dict[str, Callable[[], None]]


def log(message: str) -> None:
    print(f"[bench_throughput] {message}", file=sys.stderr, flush=True)


def rss_kib() -> int:
    """Resident set size of this process (VmRSS), KiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("VmRSS not found in /proc/self/status")


# --- network stages ---------------------------------------------------------------------------------------------
def _params(net: net_model.TPNet):
    return [(m.weight, m.bias) for m in net.stage1], [(m.weight, m.bias) for m in net.stage2]


def network_stage1(net: net_model.TPNet, layers: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Stage-1 features ``(ty, tx, F)``: tile inputs (layers + target, NaN -> 0) through the per-tile MLP."""
    return net_model.stage1_features(net_model.tile_inputs(layers, target), _params(net)[0])


def network_stage2(net: net_model.TPNet, features: torch.Tensor) -> torch.Tensor:
    """Residuals ``(ty, tx)`` from stage-1 features: the second half of ``model.frame_residual`` (clone 0, all tiles
    active): 5x5 convolution over replicate-padded features, then the per-tile rest of stage 2."""
    stage2 = _params(net)[1]
    ty, tx, n_features = features.shape
    side, radius = net_model.CLUSTER_SIDE, net_model.CLUSTER_RADIUS
    padded = F.pad(features.permute(2, 0, 1).unsqueeze(0), (radius,) * 4, mode="replicate")
    weight, bias = stage2[0]
    hidden = weight.shape[0]
    kernel = weight.view(hidden, net_model.CLUSTER_TILES, n_features).transpose(1, 2)
    kernel = kernel.reshape(hidden, n_features, side, side) * net_model.clone_masks(weight.device, weight.dtype)[0]
    z = F.conv2d(padded, kernel, bias)[0].permute(1, 2, 0)  # (ty, tx, hidden)
    if len(stage2) == 1:
        return z.squeeze(-1)
    return net_model.stage2_output(F.leaky_relu(z, net_model.NEGATIVE_SLOPE), stage2[1:])


# --- comparison -------------------------------------------------------------------------------------------------
AGREEMENT_TOL = 1e-4  # relative to max |warp|, as the twins' tests against the reference


def agreement(got, want: torch.Tensor) -> dict:
    """max |got - want| / max |want| and the number of elements with |got - want| > 1e-4 max |want|, one camera or
    pair (axis 1) at a time (no full-size temporaries)."""
    got = torch.as_tensor(got).to(want.device)
    scale = max(float(want.max()), -float(want.min())) or 1.0
    diff, over = 0.0, 0
    for i in range(want.shape[1]):
        d = (got[:, i] - want[:, i]).abs()
        diff = max(diff, float(d.max()))
        over += int((d > AGREEMENT_TOL * scale).sum())
    return {"max_rel_diff": diff / scale, "elements_over_tol": over, "elements": want.numel()}


# --- timing -----------------------------------------------------------------------------------------------------
def run_stages(label: str, stages: StageFns, sync: Callable[[], None] | None, repeat: int) -> tuple[dict, dict]:
    """Each stage in order (later stages may read earlier stages' outputs): one warm-up call, then ``repeat``
    back-to-back timed calls (the steady state of a stream of frames: the first call after another stage pays
    for cold caches, fresh allocations and idle thread pools). Returns (warm-up ms, run ms lists) by name."""
    warmup, runs = {}, {}
    for name, fn in stages.items():
        warmup[name] = timed_ms(fn, sync)
        runs[name] = [timed_ms(fn, sync) for _ in range(repeat)]
        log(f"{label} {name}: warm-up {warmup[name]:.1f} ms, runs " + ", ".join(f"{t:.1f}" for t in runs[name]) + " ms")
    return warmup, runs


def graph_option() -> str | None:
    """Name of ``TileProcessor``'s graph-capture option, or None when it has none."""
    params = inspect.signature(TileProcessor.__init__).parameters
    return next((name for name in ("use_graph", "graph", "cuda_graph", "capture") if name in params), None)


def measure_graph_replay(args, cfa, device, frames_t, target, net) -> dict:
    """``process()`` (prepare + convert + correlate, no textures) with plain launches and with the processor's
    graph option (record once, replay per frame: a CUDA graph on the GPU), and graph replay + the network."""
    option = graph_option()
    if option is None:
        return {"available": False, "note": "n/a: TileProcessor has no use_graph / graph-capture option"}
    grid = (*target.shape, 4, 9, 9)

    def sync() -> None:
        wp.synchronize_device(device)
        if target.device.type == "cuda":
            torch.cuda.synchronize(target.device)

    def time_it(graph: bool, network: bool) -> dict:
        tp = TileProcessor(args.height, args.width, cfa=cfa, device=str(device), backend="warp", **{option: graph})

        def run() -> None:
            result = tp.process(frames_t, args.disparity)
            if network:
                net.forward_frame(result.layers.view(grid), target)

        with torch.inference_mode():
            timed_ms(run, sync)  # warm-up (and recording)
            return summary([timed_ms(run, sync) for _ in range(max(args.repeat, 5))])

    out = {"available": True, "option": option, "kind": "CUDA graph" if device.is_cuda else "Warp CPU graph",
           "plain_process_ms": time_it(False, False)}
    gc.collect()
    out["graph_process_ms"] = time_it(True, False)
    gc.collect()
    out["graph_process_network_ms"] = time_it(True, True)
    gc.collect()
    out["gain"] = out["plain_process_ms"]["median"] / out["graph_process_ms"]["median"]
    out["note"] = (f"process() (prepare + convert + correlate; graph mode stages the frames into the processor's "
                   f"buffer) with {option}=False / True; median of {max(args.repeat, 5)}")
    return out


# --- soak -------------------------------------------------------------------------------------------------------
def soak(args, cfa, device, net: net_model.TPNet, frames_count: int) -> dict:
    """Stream ``frames_count`` fresh random frames through ``process`` + ``forward_frame``; RSS every 50 frames."""
    rng = np.random.default_rng(args.seed + 1)
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, device=str(device), backend="warp")
    cams = len(tables.QUAD_OFFSETS)
    samples = []
    start = time.perf_counter()
    with torch.inference_mode():
        for i in range(1, frames_count + 1):
            frames = rng.integers(0, 4096, size=(cams, tp.height, tp.width), dtype=np.uint16).astype(np.float32)
            target = torch.from_numpy(rng.uniform(-1.0, 5.0, size=(tp.tiles_y, tp.tiles_x)).astype(np.float32))
            result = tp.process(torch.from_numpy(frames), target)
            target_d = target.to(tp.torch_device)
            residual = net.forward_frame(result.layers.view(tp.tiles_y, tp.tiles_x, 4, 9, 9), target_d)
            if i == 1 or i % SOAK_EVERY == 0 or i == frames_count:
                float(residual.sum())  # reads the result back: waits for the frame's work
                samples.append({"frame": i, "rss_kib": rss_kib(), "elapsed_s": time.perf_counter() - start})
                if i % (10 * SOAK_EVERY) == 0:
                    log(f"soak: {i}/{frames_count} frames, RSS {samples[-1]['rss_kib'] / 1024:.1f} MiB")
    wp.synchronize_device(tp.device)
    elapsed = time.perf_counter() - start
    rss = np.array([s["rss_kib"] for s in samples], dtype=np.float64)
    frames_at = np.array([s["frame"] for s in samples], dtype=np.float64)
    steady = frames_at >= min(2 * SOAK_EVERY, frames_at[-1])  # after the first 100 frames
    slope = float(np.polyfit(frames_at[steady], rss[steady], 1)[0]) if steady.sum() >= 2 else float("nan")
    return {
        "frames": frames_count,
        "size": {"width": tp.width, "height": tp.height},
        "every": SOAK_EVERY,
        "what": "fresh random frames and per-tile targets each frame; TileProcessor.process (textures on, default "
                "graph setting) + TPNet.forward_frame on its layers (inference mode)",
        "graph": getattr(tp, "graph", None),
        "samples": samples,
        "first_rss_kib": int(rss[0]),
        "last_rss_kib": int(rss[-1]),
        "max_rss_kib": int(rss.max()),
        "growth_kib": int(rss[-1] - rss[0]),
        "steady_slope_kib_per_1000_frames": 1000.0 * slope,
        "frames_per_s": frames_count / elapsed,
    }


# --- the three implementations ----------------------------------------------------------------------------------
def run_warp(args, cfa, device, frames_t, target, net) -> dict:
    """Warp processor stages and the network on its layers. Returns warm-up and run timings, copies of the outputs
    the twins are compared with, and set-up facts; the processor itself is freed on return."""
    tdev = target.device
    start = time.perf_counter()
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, device=str(device), backend="warp")
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

    def stage1() -> None:
        state["features"] = network_stage1(net, layers, target)

    def stage2() -> None:
        state["residual"] = network_stage2(net, state["features"])

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
        "TP+network whole frame": tp_network,
    }
    with torch.inference_mode():
        warmup, runs = run_stages("warp", stages, sync, args.repeat)
        # The timed network split is the same computation as forward_frame: checked on this frame.
        split = network_stage2(net, network_stage1(net, layers, target))
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


# --- Taichi backend (one process per CPU thread count) ------------------------------------------------------
def run_taichi(args, cfa, device, frames_t, target, net) -> dict:
    """The Taichi processor's stages and the network on its layers, in this process (Taichi's thread count is
    that of this process); then its outputs against a Warp processor's on the same frame."""
    from tpnet_gpu import taichi_setup  # noqa: PLC0415 - imported by the Taichi worker only

    tdev = target.device
    start = time.perf_counter()
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, device=str(device), backend="taichi")
    setup_ms = 1e3 * (time.perf_counter() - start)

    def sync() -> None:
        if tdev.type == "cuda":
            taichi_setup.ti.sync()
            torch.cuda.synchronize(tdev)

    start = time.perf_counter()
    result = tp.process(frames_t, args.disparity)  # compiles the kernels or loads them from the offline cache
    sync()
    first_process_ms = 1e3 * (time.perf_counter() - start)
    layers = result.layers.view(tp.tiles_y, tp.tiles_x, 4, 9, 9)

    def tp_whole() -> None:
        tp.prepare(frames_t, args.disparity)
        tp.convert()
        tp.correlate()

    def tp_network() -> None:
        tp_whole()
        net.forward_frame(layers, target)

    stages = {"convert": tp.convert, "correlate": tp.correlate, "texture": tp.texture, "TP whole frame": tp_whole,
              "TP+network whole frame": tp_network}
    label = f"taichi ({taichi_setup.current_arch()}, {taichi_setup.threads()} CPU threads)"
    with torch.inference_mode():
        warmup, runs = run_stages(label, stages, sync, args.repeat)
    tp_whole()
    sync()
    log(f"{label}: comparing with warp ...")
    mine = {name: getattr(result, name).clone() for name in ("corr", "layers")}
    del tp, result, layers
    gc.collect()
    warp_tp = TileProcessor(args.height, args.width, cfa=cfa, device=str(device), graph=False, backend="warp")
    reference = warp_tp.process(frames_t, args.disparity)
    wp.synchronize_device(warp_tp.device)
    agree = {name: agreement(mine[name], getattr(reference, name)) for name in mine}
    return {"warmup": warmup, "runs": runs, "agreement": agree,
            "setup": {"taichi_setup_ms": setup_ms, "taichi_first_process_ms": first_process_ms,
                      "threads": taichi_setup.threads(), "arch": taichi_setup.current_arch()}}


def taichi_columns(args, is_cuda: bool) -> list[tuple[str, int | None]]:
    """(column name, CPU thread count or None) of the Taichi runs this bench makes."""
    if args.no_taichi:
        return []
    if is_cuda:
        return [("taichi-cuda", None)]
    return [(f"taichi-{n}t", n) for n in args.taichi_threads]


def spawn_taichi(argv: list[str], threads: int | None) -> dict:
    """This script again in a fresh process, as a Taichi worker with ``threads`` CPU threads; returns its report."""
    import json  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "taichi.json"
        env = dict(os.environ)
        if threads is not None:
            env["TPNET_TAICHI_THREADS"] = str(threads)
        cmd = [sys.executable, str(Path(__file__).resolve()), *argv, "--soak", "0", "--json", "",
               "--taichi-worker", str(out)]
        done = subprocess.run(cmd, env=env)
        if done.returncode != 0:
            raise SystemExit(f"taichi worker ({threads} threads) failed with exit status {done.returncode}")
        return json.loads(out.read_text())


# --- main -------------------------------------------------------------------------------------------------------
def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="Warp device: cpu, cuda, cuda:N (default: cuda if present)")
    parser.add_argument("--height", type=int, default=1936)
    parser.add_argument("--width", type=int, default=2592)
    parser.add_argument("--repeat", type=int, default=3, help="timed passes after the warm-up (default 3)")
    parser.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: torch's own)")
    parser.add_argument("--disparity", type=float, default=2.5, help="target disparity of every tile, px")
    parser.add_argument("--cfa", default=tables.DEFAULT_CFA, help="Bayer pattern, or 'mono'")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--soak", type=int, default=0, help="frames to stream for the RSS soak (default 0: none)")
    parser.add_argument("--json", default="out/bench_throughput.json", help="output JSON path ('' to skip)")
    parser.add_argument("--taichi-threads", default="1,2",
                        help="Taichi CPU thread counts, one process each (default 1,2; CPU runs only)")
    parser.add_argument("--no-taichi", action="store_true", help="skip the Taichi backend")
    parser.add_argument("--taichi-worker", default=None, help=argparse.SUPPRESS)  # internal: JSON path of a worker
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    try:
        args.taichi_threads = [int(n) for n in args.taichi_threads.split(",") if n.strip()]
    except ValueError:
        parser.error(f"--taichi-threads: expected comma-separated thread counts, got {args.taichi_threads!r}")
    if any(n < 1 for n in args.taichi_threads):
        parser.error(f"--taichi-threads: expected thread counts >= 1, got {args.taichi_threads}")
    if args.repeat < 1:
        parser.error("--repeat: expected at least 1")
    if args.soak < 0:
        parser.error("--soak: expected a number of frames >= 0")
    if args.threads is not None:
        if args.threads < 1:
            parser.error("--threads: expected at least 1")
        torch.set_num_threads(args.threads)
    cfa = None if args.cfa.lower() == "mono" else args.cfa
    init_warp()
    device = wp.get_device(args.device or default_device())
    tdev = torch.device(wp.device_to_torch(device))
    is_cuda = device.is_cuda
    torch.manual_seed(args.seed)
    net = net_model.TPNet().eval().to(tdev)  # Xavier-initialised: the timing does not depend on the weights

    soak_report = None
    if args.soak:
        log(f"soak: {args.soak} frames of {args.width}x{args.height} ...")
        soak_report = soak(args, cfa, device, net, args.soak)
        gc.collect()

    cams = len(tables.QUAD_OFFSETS)
    rng = np.random.default_rng(args.seed)
    frames = rng.integers(0, 4096, size=(cams, args.height, args.width), dtype=np.uint16).astype(np.float32)
    frames_t = torch.from_numpy(frames).to(tdev)  # float32, contiguous: the processor reads it in place
    tiles_y, tiles_x = args.height // 8, args.width // 8
    target = torch.full((tiles_y, tiles_x), args.disparity, dtype=torch.float32, device=tdev)
    if args.taichi_worker:  # a Taichi worker process: only the Taichi rows, to a JSON file for the parent
        import json  # noqa: PLC0415

        report = run_taichi(args, cfa, device, frames_t, target, net)
        Path(args.taichi_worker).write_text(json.dumps(report))
        return report
    log(f"{args.width}x{args.height}, {cams} cameras, {tiles_y * tiles_x} tiles on {device} ({device_name(device)}); "
        f"torch threads {torch.get_num_threads()}")

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

    # --- report ---------------------------------------------------------------------------------------------------
    table = []
    for name, whole_frame in ROWS:
        entry = {"name": name, "whole_frame": whole_frame}
        for impl in impls:
            entry[f"{impl}_ms"] = summary(runs[impl][name]) if name in runs.get(impl, {}) else None
            entry[f"{impl}_warmup_ms"] = warmups.get(impl, {}).get(name)
        for impl in impls[1:]:
            peer = entry[f"{impl}_ms"]
            entry[f"ratio_{impl}_over_warp"] = peer["median"] / entry["warp_ms"]["median"] if peer else None
        entry["fps"] = {impl: 1e3 / entry[f"{impl}_ms"]["median"] for impl in impls
                        if whole_frame and entry[f"{impl}_ms"]} or None
        table.append(entry)
    by_name = {e["name"]: e for e in table}

    gpu_name = device_name(device)
    tp_ms = by_name["TP whole frame"]["warp_ms"]["median"]
    tp_net_ms = by_name["TP+network whole frame"]["warp_ms"]["median"]
    if graph["available"]:  # the processor's best path: process() with graph replay
        tp_ms = min(tp_ms, graph["graph_process_ms"]["median"])
        tp_net_ms = min(tp_net_ms, graph["graph_process_network_ms"]["median"])
    full_frame = (args.height, args.width) == (1936, 2592)
    targets = {
        "gpu_tp": {"target": f"on an {TARGET_GPU}: TP <= {TARGET_TP_MS:g} ms per quad frame", "ours_ms": tp_ms,
                   "ours_is": "best of the stage launches and process() with graph replay"},
        "gpu_tp_network": {"target": f"on an {TARGET_GPU}: TP+network <= {TARGET_TP_NET_MS:g} ms per quad frame",
                           "ours_ms": tp_net_ms,
                           "ours_is": "best of the stage launches and process() with graph replay, + forward_frame"},
    }
    applies = is_cuda and TARGET_GPU in gpu_name and full_frame
    why = None if applies else ("needs a CUDA run on an H100" if not (is_cuda and TARGET_GPU in gpu_name)
                                else "needs the full 2592x1936 frame")
    for key, limit in (("gpu_tp", TARGET_TP_MS), ("gpu_tp_network", TARGET_TP_NET_MS)):
        targets[key]["met"] = (targets[key]["ours_ms"] <= limit) if applies else None
        targets[key]["not_applicable"] = why
    cpu_ratio = by_name["TP whole frame"]["ratio_numpy_over_warp"]
    cpu_applies = not is_cuda and full_frame
    targets["cpu_warp_vs_numpy"] = {
        "target": f"on CPU: Warp path >= {TARGET_CPU_RATIO:g}x the vectorised NumPy one (TP whole frame)",
        "ours_ratio": cpu_ratio,
        "met": (cpu_ratio >= TARGET_CPU_RATIO) if cpu_applies and cpu_ratio is not None else None,
        "not_applicable": None if cpu_applies else ("CPU runs only" if is_cuda else "needs the full 2592x1936 frame"),
    }
    # the CPU default backend (TileProcessor(backend=None) on the CPU is Taichi on every core) against NumPy
    tp_row = by_name["TP whole frame"]
    threads = {c: int(m.group(1)) for c in tp_row if tp_row[c] and (m := re.fullmatch(r"taichi-(\d+)t_ms", c))}
    fastest = max(threads, key=threads.get, default=None)  # the most threads: the default uses every core
    if fastest is not None and tp_row["numpy_ms"]:
        ratio = tp_row["numpy_ms"]["median"] / tp_row[fastest]["median"]
        targets["cpu_default_vs_numpy"] = {
            "target": f"on CPU: the default backend ({fastest[:-3]}) >= {TARGET_CPU_RATIO:g}x the vectorised NumPy one "
                      "(TP whole frame)",
            "ours_ratio": ratio,
            "met": (ratio >= TARGET_CPU_RATIO) if cpu_applies else None,
            "not_applicable": None if cpu_applies else ("CPU runs only" if is_cuda else "needs the full 2592x1936 frame"),
        }

    report = {
        "frame": {"width": args.width, "height": args.height, "cameras": cams, "tiles": tiles_y * tiles_x,
                  "pairs": len(tables.QUAD_PAIRS), "cfa": cfa, "target_disparity": args.disparity, "seed": args.seed,
                  "raw_values": "uniform integers 0..4095 as float32"},
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
        "targets": targets,
        "soak": soak_report,
        "device": {"warp_device": str(device), "torch_device": str(tdev), "name": gpu_name, "is_cuda": is_cuda},
        "machine": {"platform": platform.platform(), "python": platform.python_version(),
                    "cpu_count": os.cpu_count(), "cpu_model": cpu_model(), "numpy": np.__version__,
                    "warp": wp.__version__, "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
                    "threads": "Warp CPU kernels run on one thread; NumPy's BLAS and torch use all cores unless "
                               "limited (--threads for torch)",
                    "thread_env": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                                                  "MKL_NUM_THREADS")},
                    "cuda": torch.cuda.get_device_name(tdev) if tdev.type == "cuda" else None},
    }
    print_report(report)
    if args.json:
        log(f"wrote {save_json(report, args.json)}")
    return report


def _fmt_table(header, rows) -> list[str]:
    widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]
    line = " | ".join(f"{{:{'<' if i == 0 else '>'}{w}}}" for i, w in enumerate(widths))
    return [line.format(*header), "-+-".join("-" * w for w in widths)] + [line.format(*r) for r in rows]


def print_report(report: dict) -> None:
    f, t, d = report["frame"], report["timing"], report["device"]

    def ms(x):
        if x is None:
            return "-"
        return f"{x['median']:.3f}" if x["median"] < 10 else f"{x['median']:.1f}"

    def ratio(x):
        return "-" if x is None else f"{x:.2f}"

    print(f"Throughput, {f['width']}x{f['height']}, {f['cameras']} cameras ({f['cfa'] or 'mono'}), {f['tiles']} tiles, "
          f"{f['pairs']} pairs")
    print(f"device: {d['warp_device']} = {d['name']}; torch threads {report['machine']['torch_threads']}; "
          f"median of {t['repeat']} back-to-back runs after a warm-up call, per row")
    taichi = [c for c in report["columns"] if c.startswith("taichi")]
    rows = [(s["name"], ms(s["warp_ms"]), ms(s["numpy_ms"]), ms(s["torch_ms"]), *(ms(s[f"{c}_ms"]) for c in taichi),
             ratio(s["ratio_numpy_over_warp"]), ratio(s["ratio_torch_over_warp"]),
             *(ratio(s[f"ratio_{c}_over_warp"]) for c in taichi), f"{s['fps']['warp']:.2f}" if s["fps"] else "-")
            for s in report["stages"]]
    header = ("stage", "warp ms", "numpy ms", "torch ms", *(f"{c} ms" for c in taichi), "numpy/warp", "torch/warp",
              *(f"{c}/warp" for c in taichi), "fps (warp)")
    print("\n".join(_fmt_table(header, rows)))
    print("network rows: the same PyTorch TPNet for every path, on the processor's device (listed under warp); "
          "whole-frame twins: their TP, then torch_layers + that network")
    fps = {s["name"]: s["fps"] for s in report["stages"] if s["fps"]}
    for name in ("TP whole frame", "TP+network whole frame"):
        print(f"frames/s, {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in fps[name].items()))
    for impl, a in report["agreement"].items():
        if isinstance(a, dict):
            print(f"{impl} vs warp, max relative difference (elements > {AGREEMENT_TOL:g} max |warp|): " + ", ".join(
                f"{k} {v['max_rel_diff']:.2e} ({v['elements_over_tol']} of {v['elements']})" for k, v in a.items()))
    if any(isinstance(a, dict) and a["layers"]["elements_over_tol"] for a in report["agreement"].values()):
        print(f"  layers: {report['agreement']['layers_note']}")
    print(f"network split (stage 1 -> stage 2) vs forward_frame, max abs difference: "
          f"{report['agreement']['network_split_vs_forward_frame_max_abs_diff']:.2e}")
    g = report["graph_replay"]
    if g["available"]:
        print(f"graph replay ({g['kind']}, TileProcessor({g['option']}=True)): process() "
              f"{g['plain_process_ms']['median']:.3f} ms plain -> {g['graph_process_ms']['median']:.3f} ms replayed, "
              f"gain {g['gain']:.2f}x; replay + network {g['graph_process_network_ms']['median']:.3f} ms")
    else:
        print(f"graph replay gain: {g['note']}")
    p = report["paper"]
    by_name = {s["name"]: s for s in report["stages"]}
    ours = {k: by_name[k]["warp_ms"]["median"] for k in
            ("TP whole frame", "network stage 1", "network stage 2", "network whole frame", "TP+network whole frame")}
    print(f"paper ({p['gpu']}, full quad frame): TP {p['tp_ms']:.0f} ms, network {p['network_s'][0]:.2f} + "
          f"{p['network_s'][1]:.2f} s = {sum(p['network_s']):.2f} s, TP+network "
          f"{p['tp_ms'] / 1e3 + sum(p['network_s']):.3f} s")
    print(f"ours ({d['name']}, {f['width']}x{f['height']}): TP {ours['TP whole frame']:.4g} ms, network stage 1 + "
          f"stage 2 {ours['network stage 1']:.4g} + {ours['network stage 2']:.4g} ms (whole frame "
          f"{ours['network whole frame']:.4g} ms), TP+network {ours['TP+network whole frame']:.4g} ms"
          + ("" if d["is_cuda"] else " [CPU: not comparable with the paper's GPU figures]"))
    for target in report["targets"].values():
        value = target.get("ours_ms")
        got = f"ours {value:.3f} ms" if value is not None else (
            f"ours {target['ours_ratio']:.2f}x" if target.get("ours_ratio") is not None else "ours -")
        verdict = ("MET" if target["met"] else "NOT MET") if target["met"] is not None else \
            f"n/a ({target['not_applicable']})"
        print(f"target: {target['target']}: {got} -> {verdict}")
    s = report["soak"]
    if s:
        print(f"soak: {s['frames']} frames of {s['size']['width']}x{s['size']['height']} through process() + "
              f"forward_frame at {s['frames_per_s']:.1f} frames/s; RSS first {s['first_rss_kib'] / 1024:.1f} MiB "
              f"(after frame 1), last {s['last_rss_kib'] / 1024:.1f} MiB, growth {s['growth_kib'] / 1024:+.1f} MiB "
              f"(max {s['max_rss_kib'] / 1024:.1f} MiB; after frame 100: "
              f"{s['steady_slope_kib_per_1000_frames'] / 1024:+.2f} MiB per 1000 frames)")
        print("soak RSS MiB by frame: " + ", ".join(f"{x['frame']}: {x['rss_kib'] / 1024:.1f}" for x in s["samples"]))


if __name__ == "__main__":
    main()
