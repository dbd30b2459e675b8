"""Per-pixel disparity from tile answers (``tpnet_gpu/disparity/per_pixel.py``). Oracles: a pair built with a
known per-pixel disparity (a step edge at a known column: the right image's texture moved by the disparity), a
bilinear ramp's exact samples, and constant / linear tile maps whose blends are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter, map_coordinates

from tpnet_gpu.disparity.per_pixel import RADIUS, blend_field, cell_field, per_pixel, warp

EDGE = 101  # the column where the nearer surface starts (not on a tile boundary: 96 and 104)
NEAR, FAR = 10.0, 4.0


def _step_pair(h=64, w=200, seed=0):
    """``(left, right, truth)``: left[y, x] = right[y, x - d(x)], d = NEAR from column EDGE on, FAR before."""
    rng = np.random.default_rng(seed)
    right = gaussian_filter(rng.normal(size=(h, w)), 1.2) * 50 + 100
    truth = np.where(np.arange(w) >= EDGE, NEAR, FAR)[None, :].repeat(h, axis=0)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    left = map_coordinates(right, [ys, xs - truth], order=3, mode="nearest")
    return torch.tensor(left, dtype=torch.float32), torch.tensor(right, dtype=torch.float32), truth


def test_step_edge_moves_onto_the_image_edge():
    left, right, truth = _step_pair()
    ty, tx = 8, 25
    centres = 8 * np.arange(tx) + 4
    tiles = torch.tensor(np.where(centres >= EDGE, NEAR, FAR)[None, :].repeat(ty, axis=0), dtype=torch.float32)
    disparity, zncc = per_pixel(left, right, tiles)
    d = disparity.numpy()
    cells = cell_field(tiles, left.shape, 0, 0).numpy()
    usable = np.zeros_like(truth, dtype=bool)
    usable[4:-4, 16:-4] = True  # matches inside the right image, the window inside the left
    # the tile cells put the edge at column 104 (columns 101-103 wrong); per pixel it moves to 101: what is still
    # wrong lies within the ZNCC window's radius of the edge, and is less than half of the cells' error
    cells_wrong = usable & (np.abs(cells - truth) > 1)
    assert cells_wrong.sum() == 3 * 56
    wrong = usable & ~(np.abs(d - truth) <= 0.01)
    assert wrong.sum() <= cells_wrong.sum() / 2
    assert set(np.nonzero(wrong.any(axis=0))[0]) <= set(range(EDGE - RADIUS, EDGE + RADIUS))
    assert (zncc.numpy()[usable] > 0.9).mean() > 0.95


def test_pixels_whose_match_leaves_the_other_image_have_no_value():
    left, right, _ = _step_pair()
    tiles = torch.full((8, 25), 30.0)  # x - 30 < 0 for x < 30: every candidate's window reads outside
    disparity, _ = per_pixel(left, right, tiles)
    assert torch.isnan(disparity[:, :27]).all()


def test_warp_samples_a_ramp_exactly():
    ramp = torch.arange(20, dtype=torch.float32)[None, :].repeat(5, 1)
    moved = warp(ramp, torch.full((5, 20), 2.5), (1.0, 0.0))
    np.testing.assert_allclose(moved[:, 3:].numpy(), (np.arange(3, 20) - 2.5)[None, :].repeat(5, 0), atol=1e-5)
    assert torch.isnan(moved[:, :2]).all()
    left_of = warp(ramp, torch.full((5, 20), 1.0), (-1.0, 0.0))  # the right image as the reference
    np.testing.assert_allclose(left_of[:, :19].numpy(), (np.arange(19) + 1.0)[None, :].repeat(5, 0), atol=1e-5)


@pytest.mark.parametrize("nan_tile", [False, True])
def test_blend_of_a_linear_tile_map_is_linear(nan_tile):
    ty, tx = 6, 7
    tiles = torch.tensor(2.0 + 0.5 * np.arange(tx)[None, :].repeat(ty, 0), dtype=torch.float32)
    if nan_tile:
        tiles[0, 0] = float("nan")  # its weight goes to its neighbours; far from it the ramp is unchanged
    field = blend_field(tiles, (48, 56)).numpy()
    x = np.arange(56) + 0.5
    expected = 2.0 + 0.5 * (x - 4) / 8  # between the first and last tile centres
    inner = slice(4, 52)
    rows = slice(16, 48)
    np.testing.assert_allclose(field[rows, inner], np.broadcast_to(expected[inner], field[rows, inner].shape),
                               atol=1e-5)
