"""The throughput bench's floor: bytes moved and FLOPs of the tile processor's steps and of TPNET, counted from the
buffer and transform sizes, and the time they take at the H200's memory bandwidth and FP32 peak.

Counting (float32 = 4 bytes; every size from ``tpnet_gpu.layout`` and the processor's geometry):

* **bytes**: each step reads every buffer it takes and writes every buffer it makes once (the compulsory traffic
  to HBM). A tile's CLT read again for each of its pairs and a window's pixels read by the 4 tiles that overlap
  them are taken to hit the caches, so this is a lower bound. Steps: ``load`` reads the frames and writes the
  padded frames; ``centres`` reads the targets and writes the tile centres; ``convert`` reads the padded frames
  and the centres and writes the CLT; ``correlate`` reads the CLT and writes the correlations (the quad's layers
  step then reads them and writes the layers); ``fused`` (what a measurement pass runs: tile_processor.py) is
  convert + correlate without the CLT's write and read; ``texture`` is its 4 launches: imclt (CLT -> pixels), demosaic
  (pixels -> compared values), combine (both -> camera weights and RGBA contributions), overlap-add (RGBA ->
  canvas).
* **FLOPs**: matrix products as 2 m k n at the kernels' transform sizes, plus the per-frequency products (a
  multiply-add = 2). Not counted: the closed-form basis's sines and cosines, comparisons, index arithmetic, the
  texture's per-pixel demosaic and weights. Convert, per tile, camera and colour: the Bayer mask (256), the
  horizontal transforms 2 x (16x16 @ 16x8) and the vertical ones 4 x (8x16 @ 16x8). Correlate, per tile and
  pair: per colour 4 quadrants x 64 frequencies x (4 products + 3 sums + the colour-weighted sum, 2), the R/B
  low-pass (4 x 64), the normalisation (4 x 64 x 2 + 64 x 8) and the way back to lags 4 x (8x8 @ 8x15 + 15x8 @
  8x15). Texture, per tile, camera and colour: the low-pass (4 x 64) and 4 x (8x8 @ 8x16 + 16x8 @ 8x16). TPNET,
  per tile: 2 x inputs x outputs of every layer (stage 2's first layer is the 5x5 cluster: 800 inputs).

Times: ``memory_ms`` = bytes / bandwidth, ``compute_ms`` = FLOPs / FP32 peak, ``floor_ms`` = the larger (the
two overlap at best). The texture's scratch is allocated per band of tile rows but every tile's share is written
and read once per frame, so its traffic is counted for the whole frame. The pipeline's floor adds its fused
tile-processor passes (``tile_passes`` of the engine, in full-resolution passes, + one per network pass), the
texture's convert and the network; the engine's torch
work on the correlations (cost volumes, SGM) is not counted.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from tpnet_gpu import tables
from tpnet_gpu.layout import CORR_SIDE, DTT_SIZE, NET_LAYERS, NET_SIDE, PAD, TILE_SIZE, TILE_STRIDE

FLOAT = 4  # bytes
# NVIDIA H200 SXM (the GPU this project is lent): HBM3e 4.8 TB/s; FP32 (non-tensor FMA) 66.9 TFLOPS, the same
# GH100 compute as the H100 SXM5 (132 SMs x 128 FP32 lanes x 2 x 1.98 GHz). Sources looked up for this bench:
# NVIDIA's H200 product figures as quoted by aiminingco.com/gpu/h200/specs and glennklockwood.com (H100 table).
H200 = {"name": "NVIDIA H200 SXM", "hbm_bytes_per_s": 4.8e12, "fp32_flops_per_s": 66.9e12,
        "source": "4.8 TB/s HBM3e; FP32 66.9 TFLOPS (non-tensor), as the H100 SXM5 (same GH100 compute)"}
MN = DTT_SIZE * DTT_SIZE  # 64 frequencies of one quadrant


@dataclass(frozen=True)
class Work:
    """Bytes moved and floating-point operations."""

    bytes: float = 0.0
    flops: float = 0.0

    def __add__(self, other: "Work") -> "Work":
        return Work(self.bytes + other.bytes, self.flops + other.flops)

    def __mul__(self, k: float) -> "Work":
        return Work(self.bytes * k, self.flops * k)

    __rmul__ = __mul__


def matmul(m: int, k: int, n: int) -> int:
    """FLOPs of an (m x k) @ (k x n) product."""
    return 2 * m * k * n


def buffer_elements(height: int, width: int, cams: int, colours: int, pairs: int) -> dict[str, int]:
    """float32 elements each per-frame buffer of the processor (``processor.buffers.Buffers``, by its names) holds
    for the whole frame (the texture's scratch is allocated one band at a time: ``buffers.texture_band_tiles``)."""
    tiles = (height // TILE_STRIDE) * (width // TILE_STRIDE)
    side = TILE_SIZE * TILE_SIZE
    margin = TILE_STRIDE // 2
    return {
        "frames": cams * height * width,
        "padded": cams * (height + 2 * PAD) * (width + 2 * PAD),
        "disparity": tiles,
        "centres": tiles * cams * 2,
        "clt": tiles * cams * colours * 4 * MN,
        "corr": tiles * pairs * CORR_SIDE * CORR_SIDE,
        "layers": tiles * NET_LAYERS * NET_SIDE * NET_SIDE,
        "tex_pix": tiles * cams * colours * side,
        "tex_cmp": tiles * cams * colours * side,
        "tex_weights": tiles * cams * side,
        "tex_rgba": tiles * (colours + 1) * side,
        "canvas": (colours + 1) * (height + 2 * margin) * (width + 2 * margin),
    }


def tp_steps(height: int, width: int, cams: int, colours: int, pairs: int, layers: bool) -> dict[str, Work]:
    """Work of each step of one full-frame pass (see the module docstring); ``layers``: the quad's layers step."""
    e = {k: FLOAT * v for k, v in buffer_elements(height, width, cams, colours, pairs).items()}
    tiles = (height // TILE_STRIDE) * (width // TILE_STRIDE)
    convert = TILE_SIZE * TILE_SIZE + 2 * matmul(TILE_SIZE, TILE_SIZE, DTT_SIZE) + 4 * matmul(DTT_SIZE, TILE_SIZE,
                                                                                              DTT_SIZE)
    spectra = colours * 4 * MN * (4 + 3 + 2) + (4 * MN if colours == 3 else 0) + 4 * MN * 2 + MN * 8
    lags = 4 * (matmul(DTT_SIZE, DTT_SIZE, CORR_SIDE) + matmul(CORR_SIDE, DTT_SIZE, CORR_SIDE))
    texture = 4 * MN + 4 * (matmul(DTT_SIZE, DTT_SIZE, TILE_SIZE) + matmul(TILE_SIZE, DTT_SIZE, TILE_SIZE))
    convert_flops, correlate_flops = tiles * cams * colours * convert, tiles * pairs * (spectra + lags)
    steps = {
        "load": Work(e["frames"] + e["padded"]),
        "centres": Work(e["disparity"] + e["centres"]),
        "convert": Work(e["padded"] + e["centres"] + e["clt"], convert_flops),
        "correlate": Work(e["clt"] + e["corr"], correlate_flops),
        "fused": Work(e["padded"] + e["centres"] + e["corr"], convert_flops + correlate_flops),
        "texture": Work(e["clt"] + 3 * e["tex_pix"] + 2 * e["tex_cmp"] + e["tex_weights"] + 2 * e["tex_rgba"]
                        + e["canvas"], tiles * cams * colours * texture),
    }
    if layers:
        steps["correlate"] += Work(e["corr"] + e["layers"])
        steps["fused"] += Work(e["corr"] + e["layers"])
    return steps


def network_work(net, tiles: int) -> Work:
    """One ``forward_frame`` of ``net`` (``TPNet``) over ``tiles`` tiles: its layers in, stage-1 features out and
    back in, the residual out; 2 x inputs x outputs FLOPs of every linear layer per tile."""
    layers = list(net.stage1) + list(net.stage2)
    flops = sum(matmul(1, m.in_features, m.out_features) for m in layers)
    features = net.stage1[-1].out_features
    return Work(FLOAT * tiles * (NET_LAYERS * NET_SIDE * NET_SIDE + 1 + 2 * features + 1), tiles * flops)


def tp_pass(steps: dict[str, Work]) -> Work:
    """One measurement pass at new targets (``TileProcessor.measure``): centres + the fused pass."""
    return steps["centres"] + steps["fused"]


def pipeline_work(steps: dict[str, Work], net: Work | None, tile_passes: float, network_passes: int,
                  textures: bool) -> Work:
    """One ``Pipeline.process`` frame: load, the engine's ``tile_passes`` passes, each network pass (a pass + the
    network), and the texture (convert + texture)."""
    work = steps["load"] + tile_passes * tp_pass(steps)
    if net is not None:
        work += network_passes * (tp_pass(steps) + net)
    if textures:
        work += steps["centres"] + steps["convert"] + steps["texture"]
    return work


def floor(work: Work, gpu: dict = H200) -> dict:
    """Bytes, FLOPs and their time on ``gpu`` (ms): memory, compute and the floor (the larger)."""
    memory_ms = 1e3 * work.bytes / gpu["hbm_bytes_per_s"]
    compute_ms = 1e3 * work.flops / gpu["fp32_flops_per_s"]
    return {"bytes": work.bytes, "flops": work.flops, "memory_ms": memory_ms, "compute_ms": compute_ms,
            "floor_ms": max(memory_ms, compute_ms), "bound": "memory" if memory_ms >= compute_ms else "compute"}


def tp_rows_floor(height: int, width: int, colours: int, net) -> dict[str, dict]:
    """The floor of the throughput table's whole-frame rows (the quad): TP whole frame (load + one pass), network
    whole frame, TP+network whole frame."""
    steps = tp_steps(height, width, len(tables.QUAD_OFFSETS), colours, len(tables.QUAD_PAIRS), True)
    tp = steps["load"] + tp_pass(steps)
    network = network_work(net, (height // TILE_STRIDE) * (width // TILE_STRIDE))
    return {"TP whole frame": floor(tp), "network whole frame": floor(network),
            "TP+network whole frame": floor(tp + network)}


def cpu_peak(cpuinfo: str | None = None, cores: int | None = None) -> dict:
    """This CPU's FP32 peak, estimated from ``/proc/cpuinfo`` (or the text ``cpuinfo``): the cores this process may
    use x the clock (the largest "cpu MHz") x FP32 FLOPs per cycle per core from its vector units (two FMA units:
    AVX-512 64, AVX2 + FMA 32, AVX 16, else SSE 8). An estimate (turbo, thermal and shared-core effects aside): the
    roof the TP pass's FLOPs are set against, not a measurement."""
    if cpuinfo is None:
        path = Path("/proc/cpuinfo")
        cpuinfo = path.read_text() if path.exists() else ""
    cores = cores if cores is not None else len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
        else os.cpu_count() or 1
    mhz = [float(v) for v in re.findall(r"^cpu MHz\s*:\s*([0-9.]+)", cpuinfo, flags=re.M)]
    flags = set(next(iter(re.findall(r"^flags\s*:\s*(.*)$", cpuinfo, flags=re.M)), "").split())
    per_cycle = 64 if "avx512f" in flags else 32 if {"avx2", "fma"} <= flags else 16 if "avx" in flags else 8
    ghz = max(mhz) / 1e3 if mhz else float("nan")
    name = next(iter(re.findall(r"^model name\s*:\s*(.*)$", cpuinfo, flags=re.M)), "CPU").strip()
    return {"name": name, "cores": cores, "ghz": ghz, "fp32_flops_per_cycle": per_cycle,
            "fp32_flops_per_s": cores * ghz * 1e9 * per_cycle}
