"""The throughput bench's Taichi columns: ``TileProcessor(backend="taichi")`` timed in a fresh process per CPU
thread count (Taichi fixes its thread count at ``ti.init``), compared with a Warp processor on the same frame."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
import warp as wp

from tpnet_gpu.processor import TileProcessor

from tpnet_gpu.bench.throughput.throughput_common import agreement, log, run_stages

MODULE = f"{__package__}.bench_throughput"  # re-run as a worker (``--taichi-worker``): python -m MODULE


def run_taichi(args, cfa, device, frames_t, target, net) -> dict:
    """The Taichi processor's stages and the network on its layers, in this process (Taichi's thread count is
    that of this process); then its outputs against a Warp processor's on the same frame."""
    from tpnet_gpu.runtime import taichi_setup  # noqa: PLC0415 - imported by the Taichi worker only

    tdev = target.device
    start = time.perf_counter()
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, clt=True, device=str(device), backend="taichi")
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

    def tp_fused() -> None:
        tp.prepare(frames_t, args.disparity)
        tp.fused()

    def tp_network() -> None:
        tp_whole()
        net.forward_frame(layers, target)

    stages = {"convert": tp.convert, "correlate": tp.correlate, "texture": tp.texture, "TP whole frame": tp_whole,
              "TP fused whole frame": tp_fused, "TP+network whole frame": tp_network}
    label = f"taichi ({taichi_setup.current_arch()}, {taichi_setup.threads()} CPU threads)"
    with torch.inference_mode():
        warmup, runs = run_stages(label, stages, sync, args.repeat)
    tp_whole()
    sync()
    log(f"{label}: comparing with warp ...")
    mine = {name: getattr(result, name).clone() for name in ("corr", "layers")}
    tp = result = layers = None  # free the Taichi processor's buffers before the Warp one's
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
    """The throughput bench again in a fresh process (``python -m``), as a Taichi worker with ``threads`` CPU
    threads; returns its report."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "taichi.json"
        env = dict(os.environ)
        if threads is not None:
            env["TPNET_TAICHI_THREADS"] = str(threads)
        cmd = [sys.executable, "-m", MODULE, *argv, "--soak", "0", "--json", "",
               "--taichi-worker", str(out)]
        done = subprocess.run(cmd, env=env)
        if done.returncode != 0:
            raise SystemExit(f"taichi worker ({threads} threads) failed with exit status {done.returncode}")
        return json.loads(out.read_text())
