"""TPNET's context step (net/context.py) on hand-made disparity grids.

Oracles: a known plane (a plane's mean over a symmetric window is its centre value) with seeded Gaussian noise of
known sigma (a mean of n independent errors has sigma / sqrt(n)), a known step edge (the side each tile belongs
to), and grids whose weighted means are worked out by hand.
"""

import numpy as np
import pytest
import torch

from tpnet_gpu.net.context import CONTEXT_BAND, CONTEXT_SIZE, context_step

TY, TX = 30, 40
SIGMA = 0.05  # px: noise well inside CONTEXT_BAND, so each interior tile averages all 25 of its window
R = CONTEXT_SIZE // 2  # tiles within R of the grid's edge have part of their window outside it
INTERIOR = (slice(R, -R), slice(R, -R))


def plane(step: float = 0.0) -> np.ndarray:
    """``(TY, TX)`` disparity of a slanted plane, plus ``step`` px on the right half (a depth edge at x = TX/2)."""
    y, x = np.mgrid[0:TY, 0:TX]
    return 5.0 + 0.03 * x + 0.02 * y + np.where(x >= TX // 2, step, 0.0)


def run(disparity: np.ndarray, strength: np.ndarray | None = None) -> np.ndarray:
    strength = np.ones_like(disparity) if strength is None else strength
    return context_step(torch.from_numpy(disparity.astype(np.float32)),
                        torch.from_numpy(strength.astype(np.float32))).numpy().astype(np.float64)


def test_a_clean_plane_is_kept():
    """Oracle: a plane's mean over the full 5x5 window is its centre value. Tolerance: 1e-5 px (float32 of
    ~6 px) on the tiles whose whole window is inside the grid."""
    truth = plane()
    out = run(truth)
    np.testing.assert_allclose(out[INTERIOR], truth[INTERIOR], rtol=0, atol=1e-5)


def test_noise_on_a_plane_is_cut():
    """Oracle: independent N(0, SIGMA) noise (seed 0) on a known plane: the mean of the 25 tiles of each interior
    window has an error of sigma / 5 (the neighbouring means are correlated, not the per-tile error). Tolerance:
    RMSE after <= 0.27 x RMSE before (expected 0.20; a 3x3 window gives 0.33, the unchanged grid 1.0)."""
    assert CONTEXT_SIZE == 5
    truth = plane()
    noisy = truth + np.random.default_rng(0).normal(0.0, SIGMA, truth.shape)
    out = run(noisy)
    before = np.sqrt(np.mean((noisy - truth)[INTERIOR] ** 2))
    after = np.sqrt(np.mean((out - truth)[INTERIOR] ** 2))
    assert after <= 0.27 * before, f"RMSE {before:.4f} -> {after:.4f} px"


def test_a_step_edge_stays_where_it_is():
    """Oracle: a 2 px step (> CONTEXT_BAND) in a noisy plane: every tile averages only with its own side, so each
    stays within 4 SIGMA of its own side's plane (the noise-free mean of a one-sided 5x5 window is off the centre
    by at most a slope of 0.03 px / tile x 1 tile) and the edge column does not move."""
    truth = plane(step=2.0)
    noisy = truth + np.random.default_rng(1).normal(0.0, SIGMA, truth.shape)
    out = run(noisy)
    assert np.abs(out - truth).max() <= 4 * SIGMA
    right = out - plane() > 1.0  # nearer than the midpoint between the two sides
    np.testing.assert_array_equal(right, np.broadcast_to(np.arange(TX) >= TX // 2, (TY, TX)))


def test_weights_band_and_missing_tiles_by_hand():
    """Oracle: a 3x3 grid worked by hand. Centre 1.2 (strength 1), six neighbours 1.0 (strength 1), one at 1.6
    (strength 0: weighs nothing), one at 3.0 (beyond CONTEXT_BAND of 1.2: another surface): the centre becomes
    (1.2 + 6 x 1.0) / 7. A NaN tile stays NaN and weighs nothing (a NaN in place of the 3.0 changes no other
    tile); a tile whose surface weighs 0 keeps its value."""
    assert CONTEXT_BAND == 0.5  # the hand values below lie on either side of this band
    grid = np.array([[1.0, 1.0, 1.0], [1.0, 1.2, 1.6], [1.0, 1.0, 3.0]])
    strength = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
    out = run(grid, strength)
    assert out[1, 1] == pytest.approx((1.2 + 6 * 1.0) / 7, abs=1e-6)
    assert out[2, 2] == pytest.approx(3.0, abs=1e-6)  # alone on its surface: its own value
    with_nan = grid.copy()
    with_nan[2, 2] = np.nan
    out_nan = run(with_nan, strength)
    assert np.isnan(out_nan[2, 2])
    np.testing.assert_allclose(np.delete(out_nan.ravel(), 8), np.delete(out.ravel(), 8), rtol=0, atol=1e-6)
    zero = run(grid, np.zeros_like(grid))
    np.testing.assert_array_equal(zero, grid.astype(np.float32).astype(np.float64))


def test_the_window_reaches_two_tiles_by_hand():
    """Oracle: a 5x5 grid worked by hand, strengths 1. The centre 1.2 and its 24 neighbours at 1.0 (all within
    CONTEXT_BAND): (1.2 + 24) / 25 (a 3x3 window gives (1.2 + 8) / 9). With the outer ring at 3.0 (another
    surface) only the inner 3x3 counts, and a corner of that ring averages with the 3 ring tiles of its own 3x3
    corner of the grid: 3.0."""
    grid = np.ones((5, 5))
    grid[2, 2] = 1.2
    assert run(grid)[2, 2] == pytest.approx((1.2 + 24) / 25, abs=1e-6)
    ring = np.full((5, 5), 3.0)
    ring[1:4, 1:4] = 1.0
    ring[2, 2] = 1.2
    out = run(ring)
    assert out[2, 2] == pytest.approx((1.2 + 8) / 9, abs=1e-6)
    assert out[0, 0] == pytest.approx(3.0, abs=1e-6)


def test_bad_strength_is_refused():
    with pytest.raises(ValueError, match=r"strength: expected the shape of disparity, a \(tiles_y, tiles_x\) grid "
                                         r"\(3, 4\), got \(4, 3\)"):
        context_step(torch.zeros(3, 4), torch.zeros(4, 3))
