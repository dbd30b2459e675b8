"""The Warp tile kernels at CUDA's block size, on the CPU: Warp runs a tiled launch with 64 logical lanes per
block as cooperative fibers (``wp.config.enable_cpu_blocks``), so what differs between a 1-lane and a 64-lane
block (scalar code run by every lane, tile ops spread over lanes, barriers, early returns) is exercised without a
GPU. Both tile passes: split (textures=True: convert, correlate, texture) and fused (one pass, no CLT tiles).
Oracle: the same processor at 1 lane per block; tolerance: bitwise equal. In a subprocess, because the setting
is global to a process."""

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import warp as wp
    wp.config.enable_cpu_blocks = True
    from tpnet_gpu.layout import CUDA_BLOCK_DIM
    from tpnet_gpu.processor import TileProcessor
    H, W = 48, 64
    rng = np.random.default_rng(3)
    frames = rng.uniform(0, 1000, size=(4, H, W)).astype(np.float32)
    frames[1, 20, 30] = np.nan
    disparity = rng.uniform(-4, 4, size=(H // 8, W // 8)).astype(np.float32)
    disparity[2, 3] = np.nan
    disparity[0, 0] = 40.0
    active = np.ones((H // 8, W // 8), bool)
    active[4, 5] = False
    kernels = rng.normal(size=(4, 2, 3, 3, 4, 8, 8)).astype(np.float32) * 0.1
    kernels[..., 0, :, :] += 1.0
    bad = 0
    kinds = (("GRBG", {}), ("mono", {"cfa": None}), ("kernel grid", {"kernels": kernels}))
    cases = [(label, kw, split) for label, kw in kinds for split in (True, False)]
    for label, kw, split in cases:
        out = {}
        names = ("clt", "corr", "layers", "valid", "texture") if split else ("corr", "layers", "valid")
        for block_dim in (1, CUDA_BLOCK_DIM):
            tp = TileProcessor(H, W, textures=split, clt=split, device="cpu", backend="warp", graph=False, **kw)
            tp._backend.block_dim = block_dim
            r = tp.process(frames, disparity, active=active)
            out[block_dim] = {k: getattr(r, k).clone() for k in names}
        diff = {k: float((out[CUDA_BLOCK_DIM][k].float() - out[1][k].float()).abs().nan_to_num(1e30).max())
                for k in out[1]}
        bad += any(diff.values())
        print(label, "split" if split else "fused", diff)
    sys.exit(1 if bad else 0)
""")


@pytest.mark.slow
def test_tile_kernels_at_64_lanes_equal_one_lane(tmp_path):
    script = tmp_path / "cpu_blocks.py"  # Warp kernels and their callers must live in a file
    script.write_text(SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr[-3000:]
