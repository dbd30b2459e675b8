"""Per-pixel disparity from tile answers (``tpnet_gpu/disparity/per_pixel.py``). Oracles: a pair built with a
known per-pixel disparity (a step edge at a known column: the right image's texture moved by the disparity), a
bilinear ramp's exact samples, constant / linear tile maps whose blends are known in closed form, and ZNCC
summed window by window in float64 (NumPy)."""

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


def _zncc_float64(reference: np.ndarray, moved: np.ndarray, radius: int) -> np.ndarray:
    """ZNCC of each pixel's (2 radius + 1)^2 window (edge-replicated), summed window by window in float64; -1 where
    the moved window holds NaN; the denominator floored as ``per_pixel`` floors it (1e-6 of the image's variance)."""
    k = 2 * radius + 1
    ref = np.lib.stride_tricks.sliding_window_view(np.pad(reference, radius, mode="edge"), (k, k))
    mov = np.lib.stride_tricks.sliding_window_view(np.pad(moved, radius, mode="edge"), (k, k))
    rc = ref - ref.mean(axis=(-2, -1), keepdims=True)
    with np.errstate(invalid="ignore"):
        mc = mov - mov.mean(axis=(-2, -1), keepdims=True)
        cov = (rc * mc).mean(axis=(-2, -1))
        denom = np.sqrt(rc.var(axis=(-2, -1)) * mc.var(axis=(-2, -1)))
    z = cov / np.maximum(denom, 1e-6 * reference.var() + 1e-12)
    return np.where(np.isnan(mov).any(axis=(-2, -1)), -1.0, z)


@pytest.mark.parametrize("level", [0.0, 1000.0])
def test_zncc_matches_window_sums_in_float64(level):
    # one integer disparity for every tile: every candidate is the same shift, so the returned ZNCC is that
    # shift's; a bright image (level 1000, contrast 10) is where float32 running sums would lose the windows
    rng = np.random.default_rng(3)
    h, w, d = 48, 96, 5
    right = gaussian_filter(rng.normal(size=(h, w)), 1.0) * 10 + level
    left = np.roll(right, d, axis=1) + rng.normal(scale=0.5, size=(h, w))
    moved = np.full((h, w), np.nan)
    moved[:, d:] = right[:, :-d]  # right[y, x - d]; NaN where that leaves the image
    tiles = torch.full((h // 8, w // 8), float(d))
    _, z = per_pixel(torch.tensor(left, dtype=torch.float32), torch.tensor(right, dtype=torch.float32), tiles)
    expected = _zncc_float64(left, moved, RADIUS)
    assert (expected[:, : d + RADIUS] == -1).all() and (expected[:, d + RADIUS:] > 0.5).mean() > 0.95
    np.testing.assert_allclose(z.numpy(), expected, atol=2e-5)


@pytest.mark.parametrize("offset", [(1.0, 0.0), (0.0, -1.0), (0.6, 0.8)])
def test_best_zncc_is_the_best_candidates_in_float64(offset):
    # tiles of different disparities, some NaN: each pixel's ten candidates differ, so each candidate's window
    # sums must be its own (the step reuses its buffers from one candidate to the next); oracle: every candidate
    # field moved by SciPy's bilinear sampling and its ZNCC summed window by window in float64, the best kept
    rng = np.random.default_rng(5)
    h, w = 40, 64
    other = gaussian_filter(rng.normal(size=(h, w)), 1.0) * 10 + 50
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    reference = map_coordinates(other, [ys - 3 * offset[1], xs - 3 * offset[0]], order=3, mode="nearest")
    reference += rng.normal(scale=0.5, size=(h, w))  # the other camera sees it at disparity 3
    tiles = torch.tensor(rng.uniform(1.0, 6.0, size=(h // 8, w // 8)), dtype=torch.float32)
    tiles[1, 2] = tiles[3, 5] = float("nan")
    _, z = per_pixel(torch.tensor(reference, dtype=torch.float32), torch.tensor(other, dtype=torch.float32), tiles,
                     offset=offset)
    fields = [blend_field(tiles, (h, w))] + [cell_field(tiles, (h, w), dy, dx)
                                              for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    best = np.full((h, w), -1.0)
    for field in fields:
        d = field.numpy().astype(np.float64)
        at_x, at_y = xs - d * offset[0], ys - d * offset[1]
        inside = (at_x >= 0) & (at_x <= w - 1) & (at_y >= 0) & (at_y <= h - 1)  # False where d is NaN
        sampled = map_coordinates(other, [np.nan_to_num(at_y), np.nan_to_num(at_x)], order=1, mode="nearest")
        best = np.maximum(best, _zncc_float64(reference, np.where(inside, sampled, np.nan), RADIUS))
    assert (best > 0.5).mean() > 0.2  # the oracle is not all -1: the windows that match are compared too
    np.testing.assert_allclose(z.numpy(), best, atol=5e-5)
