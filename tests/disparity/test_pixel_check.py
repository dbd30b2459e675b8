"""The per-pixel left-right check, the background fill and the tile answers from checked pixels
(``tpnet_gpu/disparity/pixel_check.py``). Oracles: hand-made maps whose matches are counted by hand, the
half-sine window's weighted mean computed here with NumPy loops, and a two-surface pair built from its geometry
(a near plane in front of a far one, each camera seeing what is nearer): the strip of the far surface that only
the left camera sees is NEAR - FAR px wide, left of the near plane's edge."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter, map_coordinates

from tpnet_gpu.disparity.per_pixel import per_pixel
from tpnet_gpu.disparity.pixel_check import AGREE_PX, MIN_MEASURED, fill_background, left_right, tile_answers

NAN = float("nan")


def test_left_right_counts_by_hand():
    pixels = torch.full((3, 10), 2.0)
    other = torch.full((3, 10), 2.0)
    other[1, 5] = 4.0  # the left pixel (7, 1) lands on it: 4 - 2 > 1 px, not measured
    other[2, 3] = NAN  # (5, 2) lands on a pixel the other view has no answer for
    ok = left_right(pixels, other, (1.0, 0.0)).numpy()
    expected = np.ones((3, 10), dtype=bool)
    expected[:, :2] = False  # x - 2 < 0: the match leaves the image
    expected[1, 7] = expected[2, 5] = False
    np.testing.assert_array_equal(ok, expected)
    pixels[0, 4] = NAN
    assert not left_right(pixels, other, (1.0, 0.0))[0, 4]
    # a vertical baseline: the other camera below, the match at y - d
    tall = torch.full((6, 2), 1.5)  # rounds to one row up (y - 1.5 -> nearest y - 1 or y - 2, half to even)
    ok = left_right(tall, torch.full((6, 2), 1.5), (0.0, 1.0)).numpy()
    assert not ok[:1].any() and ok[2:].all()


def test_fill_background_takes_the_nearer_smaller_neighbour():
    rows = torch.tensor([[1.0, NAN, NAN, 5.0], [NAN, 3.0, NAN, NAN], [NAN, NAN, NAN, NAN], [7.0, NAN, 2.0, 9.0]])
    filled = fill_background(rows, (1.0, 0.0)).numpy()
    np.testing.assert_array_equal(filled[0], [1, 1, 1, 5])  # between 1 and 5: the smaller (the far surface)
    np.testing.assert_array_equal(filled[1], [3, 3, 3, 3])  # one side only: that side
    assert np.isnan(filled[2]).all()  # nothing on the line
    np.testing.assert_array_equal(filled[3], [7, 2, 2, 9])
    np.testing.assert_array_equal(fill_background(rows.t(), (0.0, -1.0)).numpy(), filled.T)  # columns


def _window_mean(image, ty, tx, weight):
    """The half-sine-weighted mean of the finite pixels of tile (ty, tx)'s window (start 8 t - 4), by loops."""
    h, w = image.shape
    num = den = 0.0
    for i in range(16):
        for j in range(16):
            y, x = 8 * ty - 4 + i, 8 * tx - 4 + j
            if 0 <= y < h and 0 <= x < w and np.isfinite(image[y, x]):
                num += weight[i, j] * image[y, x]
                den += weight[i, j]
    return num / den, den


def test_tile_answers_are_window_means_backed_by_agreeing_pixels():
    s = np.sin(np.pi * (np.arange(16) + 0.5) / 16)
    weight = np.outer(s, s)
    h, w = 32, 48
    image = np.where(np.arange(w)[None, :] >= 20, 12.0, 4.0).repeat(h, 0)  # a step at column 20
    image[:, 30:34] += np.linspace(0, 0.6, 4)  # and a little slope, still within 1 px
    filled = torch.tensor(image, dtype=torch.float32)
    measured = torch.ones(h, w, dtype=torch.bool)
    fallback = torch.full((4, 6), 99.0)
    answer, confidence = tile_answers(filled, measured, fallback)
    for ty in range(4):
        for tx in range(6):
            mean, _ = _window_mean(image, ty, tx, weight)
            assert answer[ty, tx] == pytest.approx(mean, abs=1e-4)
            inside = [(i, j) for i in range(16) for j in range(16) if 0 <= 8 * ty - 4 + i < h and
                      0 <= 8 * tx - 4 + j < w]
            backing = sum(weight[i, j] for i, j in inside
                          if abs(image[8 * ty - 4 + i, 8 * tx - 4 + j] - mean) <= AGREE_PX)
            assert confidence[ty, tx] == pytest.approx(backing / weight.sum(), abs=1e-5)
    assert confidence[1, 2] == 0  # window x 12..27 straddles 4 | 12: its mean 8.x is neither surface
    assert confidence[1, 4] == pytest.approx(1.0, abs=1e-6)  # a whole window of one surface backs it
    # where measured pixels hold less than MIN_MEASURED of a window's weight, the fallback stands
    sparse = torch.zeros(h, w, dtype=torch.bool)
    sparse[:, 36] = True  # one column: tile 5's window (36..51) has it first, tile 4's (28..43) ninth
    answer, confidence = tile_answers(filled, sparse, fallback)
    assert weight[:, 8].sum() / weight.sum() < MIN_MEASURED
    assert answer[1, 5] == 99.0 and answer[1, 4] == 99.0 and answer[1, 2] == 99.0
    assert confidence[1, 2] == 0  # none of its pixels measured: nothing backs 99


def _two_planes(h=48, w=160, edge=90, near=11.0, far=5.0, seed=1):
    """``(left, right, truth_left, truth_right)``: a far plane (disparity ``far``) and, from left-view column
    ``edge`` on, a near one (``near``), each with its own texture fixed to the surface (in left-view columns).
    The right camera sees a left-view column x at x - d: the near plane from column edge - near on, the far one
    left of it - so left columns edge - (near - far) .. edge of the far plane are hidden from it."""
    rng = np.random.default_rng(seed)
    textures = [gaussian_filter(rng.normal(size=(h, w + 40)), 1.2) * 50 + 100 for _ in range(2)]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)

    def sample(tex, cols):
        return map_coordinates(tex, [ys, cols + 20], order=3, mode="nearest")

    truth_left = np.where(xs >= edge, near, far)
    left = np.where(xs >= edge, sample(textures[1], xs), sample(textures[0], xs))
    truth_right = np.where(xs >= edge - near, near, far)
    right = np.where(xs >= edge - near, sample(textures[1], xs + near), sample(textures[0], xs + far))
    to = lambda a: torch.tensor(a, dtype=torch.float32)  # noqa: E731
    return to(left), to(right), truth_left, truth_right


def _tiles(truth):
    """Tile answers: each tile the truth at its centre column (a tile engine's answer, edge fattening and all)."""
    return torch.tensor(truth[4::8, 4::8], dtype=torch.float32)


def test_the_half_occluded_strip_is_caught_and_filled_with_the_far_surface():
    left, right, truth_left, truth_right = _two_planes()
    mine, _ = per_pixel(left, right, _tiles(truth_left), offset=(1.0, 0.0))
    theirs, _ = per_pixel(right, left, _tiles(truth_right), offset=(-1.0, 0.0))
    measured = left_right(mine, theirs, (1.0, 0.0)).numpy()
    strip = np.zeros_like(measured)
    strip[8:-8, 90 - 6: 90] = True  # the far plane's columns only the left camera sees
    seen = np.zeros_like(measured)
    seen[8:-8, 16:-8] = True
    seen &= ~strip
    seen[:, 90 - 9: 90 + 4] = False  # within the ZNCC window's reach of the edges
    assert measured[strip].mean() < 0.2  # most of the hidden strip fails the check
    assert measured[seen].mean() > 0.95  # what both see passes
    wrong = seen & measured & ~(np.abs(mine.numpy() - truth_left) <= 1)
    assert wrong.sum() == 0
    filled = fill_background(torch.where(torch.tensor(measured), mine, torch.full_like(mine, NAN)),
                             (1.0, 0.0)).numpy()
    assert (np.abs(filled[strip] - 5.0) <= 1).mean() > 0.95  # the strip gets the far surface
    without = np.abs(mine.numpy()[strip] - 5.0) <= 1  # the unchecked map: the near surface spills over it
    assert without.mean() < (np.abs(filled[strip] - 5.0) <= 1).mean()
