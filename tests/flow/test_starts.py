"""The flow's coarse start (tpnet_gpu/flow/starts.py). Oracles: block means written out by slicing, the nearest
coarse tile found by brute force over the tile centres' pixel positions, and an exact Fourier shift of a texture
beyond the full-resolution search's reach (2 x 6 px)."""

import numpy as np
import pytest
import torch

from tpnet_gpu.flow import FlowConfig, FlowEstimator
from tpnet_gpu.flow.starts import bin_frames, coarse_size, scaled_start
from tests.flow.test_estimator import _fourier_shift


def test_bin_frames_is_the_mean_of_2x2_blocks():
    frames = torch.rand(2, 36, 52)
    binned = bin_frames(frames, (16, 24)).numpy()
    f = frames.numpy()
    blocks = (f[:, 0::2, 0::2] + f[:, 1::2, 0::2] + f[:, 0::2, 1::2] + f[:, 1::2, 1::2]) / 4
    np.testing.assert_allclose(binned, blocks[:, :16, :24], rtol=1e-6)


def test_coarse_size_keeps_whole_tiles():
    assert coarse_size(240, 320) == (120, 160)
    assert coarse_size(72, 96) == (32, 48)  # 36 rows crop to 32
    assert coarse_size(32, 64) == (16, 32)  # one window's rows
    assert coarse_size(24, 64) is None  # 12 rows crop to 8: less than a window


def test_scaled_start_takes_the_nearest_coarse_tile_doubled():
    coarse = torch.arange(4 * 5 * 2, dtype=torch.float32).reshape(4, 5, 2)
    start = scaled_start(coarse, (9, 11)).reshape(9, 11, 2).numpy()
    for ty in range(9):
        for tx in range(11):
            # fine centre in full-resolution px, coarse centres (8 c + 4) * 2
            dy = np.abs(2 * (8 * np.arange(4) + 4) - (8 * ty + 4))
            dx = np.abs(2 * (8 * np.arange(5) + 4) - (8 * tx + 4))
            if 8 * tx + 4 >= 2 * 8 * 5 or 8 * ty + 4 >= 2 * 8 * 4:  # beyond the coarse frame
                assert np.isnan(start[ty, tx]).all()
            else:
                np.testing.assert_array_equal(start[ty, tx], 2 * coarse[np.argmin(dy), np.argmin(dx)].numpy())


@pytest.fixture(scope="module")
def texture():
    from scipy import ndimage

    from tpnet_gpu.scenes import textures as tx

    image = tx.noise_texture(np.random.default_rng(5), 256)[..., 1].astype(np.float64) * 1000.0
    return ndimage.gaussian_filter(image, 0.7, mode="wrap")


def test_flow_beyond_the_search_is_found_from_the_binned_frames(texture):
    """16 px is beyond the full-resolution search (starts 6 px around 0, each reaching 6 px): the binned level
    (8 px there) finds it. Tolerance: median error 0.05 px (measured ~0.003) on > 35 % of the tiles (45 %
    measured: the shift moves the right-hand tiles' windows off the frame); without the level < 10 % are found
    (the check fails with the level broken)."""
    moved = _fourier_shift(texture, 16.0, -1.0)[:48, :96].astype(np.float32)
    still = texture[:48, :96].astype(np.float32)
    found = {}
    for levels in (1, 0):
        est = FlowEstimator(48, 96, cams=1, cfa=None, config=FlowConfig(levels=levels), backend="warp", device="cpu")
        result = est.estimate(still, moved)
        flow, valid = result.flow.numpy(), result.valid.numpy()
        error = np.linalg.norm(flow - np.array([16.0, -1.0]), axis=-1)
        found[levels] = (valid & (error < 0.5))[1:-1, 1:-1].mean()
        if levels:
            assert np.median(error[valid]) < 0.05
    assert found[1] > 0.35 and found[0] < 0.1, found
