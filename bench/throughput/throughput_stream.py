"""The throughput bench's stream measurements: the graph-replay gain of ``TileProcessor`` (CUDA graph on the
GPU, Warp CPU graph on the CPU) and the memory soak (process RSS over a stream of fresh frames)."""

from __future__ import annotations

import gc
import inspect
import time

import numpy as np
import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.net import model as net_model
from tpnet_gpu.processor import TileProcessor

from tpnet_gpu.bench.common import random_frames, summary, timed_ms
from tpnet_gpu.bench.throughput.throughput_common import log

SOAK_EVERY = 50  # frames between RSS samples


def rss_kib() -> int:
    """Resident set size of this process (VmRSS), KiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("VmRSS not found in /proc/self/status")


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


def soak(args, cfa, device, net: net_model.TPNet, frames_count: int) -> dict:
    """Stream ``frames_count`` fresh random frames through ``process`` + ``forward_frame``; RSS every 50 frames."""
    rng = np.random.default_rng(args.seed + 1)
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, clt=True, device=str(device), backend="warp")
    cams = len(tables.QUAD_OFFSETS)
    samples = []
    start = time.perf_counter()
    with torch.inference_mode():
        for i in range(1, frames_count + 1):
            frames = random_frames(rng, args.height, args.width, cams)
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
        "size": {"width": args.width, "height": args.height},
        "every": SOAK_EVERY,
        "what": "fresh random frames and per-tile targets each frame; TileProcessor.process (textures on, default "
                "graph setting) + TPNet.forward_frame on its layers (inference mode)",
        "graph": tp.graph,
        "samples": samples,
        "first_rss_kib": int(rss[0]),
        "last_rss_kib": int(rss[-1]),
        "max_rss_kib": int(rss.max()),
        "growth_kib": int(rss[-1] - rss[0]),
        "steady_slope_kib_per_1000_frames": 1000.0 * slope,
        "frames_per_s": frames_count / elapsed,
    }
