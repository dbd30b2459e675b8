"""The throughput bench's pipeline rows and floor (bench/throughput/throughput_pipeline.py, throughput_floor.py).

Oracles: the processor's own buffers (the counted bytes must be their sizes), hand-counted matrix-product FLOPs
and the network's weight count (a linear layer costs 2 FLOPs per weight per tile), an unclocked pipeline (the
stage clock must not change a frame's results, its stages must add up to the frame and it must leave the
instances as they were)."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from tpnet_gpu import tables
from tpnet_gpu.bench.throughput import throughput_floor as fl
from tpnet_gpu.bench.throughput.throughput_pipeline import STAGES, StageClock, parse_sizes, scene_frames
from tpnet_gpu.processor.buffers import texture_band_tiles
from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.pipeline import Pipeline
from tpnet_gpu.processor import TileProcessor

H, W = 32, 48  # 4 x 6 tiles


def test_counted_bytes_are_the_processor_buffers():
    tp = TileProcessor(H, W, textures=True, clt=True, device="cpu", backend="warp")
    counted = fl.buffer_elements(H, W, tp.cams, tp.colours, len(tp.pairs))
    band = texture_band_tiles(tp.tiles_y, tp.tiles_x) / tp.tiles  # the scratch holds one band of the frame
    for name, elements in counted.items():
        share = band if name in ("tex_pix", "tex_cmp", "tex_weights") else 1
        assert getattr(tp._buffers, name).size == elements * share, name


def test_counted_flops_of_one_tile():
    steps = fl.tp_steps(8, 8, 1, 1, 1, layers=False)  # one tile, one camera, mono, one pair
    # convert: mask 256 + 2 x (16x16 @ 16x8) = 2 x 4096 + 4 x (8x16 @ 16x8) = 4 x 2048
    assert steps["convert"].flops == 256 + 8192 + 8192
    # correlate: 4 x 64 x 9 products, 4 x 64 x 2 + 64 x 8 normalisation, lags 4 x (1920 + 3600)
    assert steps["correlate"].flops == 2304 + 1024 + 22080
    assert steps["texture"].flops == 256 + 4 * (2048 + 4096)


def test_network_flops_are_two_per_weight_and_tile():
    net = TPNet()
    weights = sum(p.numel() for name, p in net.named_parameters() if name.endswith("weight"))
    assert fl.network_work(net, 10).flops == 2 * weights * 10


def test_floor_is_the_slower_of_memory_and_compute():
    gpu = {"hbm_bytes_per_s": 1e12, "fp32_flops_per_s": 1e13}
    f = fl.floor(fl.Work(bytes=2e9, flops=1e10), gpu)
    assert f["memory_ms"] == pytest.approx(2.0) and f["compute_ms"] == pytest.approx(1.0)
    assert f["floor_ms"] == f["memory_ms"] and f["bound"] == "memory"


def test_cpu_peak_is_cores_times_clock_times_vector_width():
    # by hand: 2 cores x 2.5 GHz x 32 FP32 FLOP/cycle (AVX2 + FMA: two 8-wide FMA units) = 160 GFLOPS; AVX-512: 64
    info = "model name\t: Test CPU\ncpu MHz\t\t: 2400.000\nflags\t\t: sse avx avx2 fma\ncpu MHz\t\t: 2500.000\n"
    peak = fl.cpu_peak(info, cores=2)
    assert (peak["name"], peak["ghz"], peak["fp32_flops_per_cycle"]) == ("Test CPU", 2.5, 32)
    assert peak["fp32_flops_per_s"] == pytest.approx(160e9)
    assert fl.cpu_peak(info.replace("avx2 fma", "avx2 fma avx512f"), cores=1)["fp32_flops_per_s"] == pytest.approx(160e9)
    assert fl.cpu_peak("flags : sse\ncpu MHz : 1000\n", cores=4)["fp32_flops_per_s"] == pytest.approx(32e9)


def test_pipeline_frame_counts_every_pass():
    steps = fl.tp_steps(H, W, 4, 3, 6, layers=True)
    net = fl.Work(1.0, 2.0)
    one = fl.pipeline_work(steps, net, 0.0, 1, False)
    two = fl.pipeline_work(steps, net, 1.0, 1, False)
    assert two.bytes - one.bytes == pytest.approx(fl.tp_pass(steps).bytes)
    assert one.flops == pytest.approx(fl.tp_pass(steps).flops + 2.0)


def test_parse_sizes():
    assert parse_sizes("640x480, 2592x1936") == [(640, 480), (2592, 1936)] and parse_sizes("") == []
    for bad in ("640", "641x480", "8x8", "axb"):
        with pytest.raises(ValueError, match="--pipeline-sizes"):
            parse_sizes(bad)


def test_stage_clock_partitions_a_frame_and_changes_nothing():
    frames = scene_frames(64, 48, "demo", 0)
    pipe = Pipeline(48, 64, device="cpu", backend="warp")
    with torch.inference_mode():
        want = pipe.process(frames).disparity.clone()
        clock = StageClock(pipe, lambda: None)
        with clock.hooked():
            assert "run" in vars(pipe.engine)
            start = time.perf_counter()
            stages = clock.frame(frames)
            elapsed_ms = 1e3 * (time.perf_counter() - start)
            marks = [label for label, _ in clock.marks]
            got = pipe.process(frames).disparity.clone()
    assert set(stages) == set(STAGES) and all(stages[s] > 0 for s in STAGES)
    assert 0.95 * elapsed_ms < sum(stages.values()) <= elapsed_ms  # the stages cover the frame, no more
    assert marks == ["engine search", "engine refine", "network", "texture", "rest"]
    np.testing.assert_array_equal(got.numpy(), want.numpy())
    assert "run" not in vars(pipe.engine) and "texture" not in vars(pipe.network_tp)
    assert pipe._infer.__name__ == "infer" and type(pipe.engine).run is DisparityEngine.run
    assert pipe.engine.tp.pairs == tables.QUAD_PAIRS


def test_startup_bench_rejects_a_bad_size(capsys):
    """bench_startup reads its sizes with the same parser: a bad one exits with the option named."""
    from tpnet_gpu.bench.throughput import bench_startup  # noqa: PLC0415

    with pytest.raises(SystemExit):
        bench_startup.main(["--sizes", "641x480"])
    assert "--sizes: expected multiples of 8" in capsys.readouterr().err
