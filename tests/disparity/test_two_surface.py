"""Two-surface tiles (tpnet_gpu/disparity/two_surface.py). Oracle: a synthetic quad frame of two textures either
side of a vertical edge with known disparities - a foreground board (left of the edge, disparity D_FG) over a
background (D_BG), each camera's pixels drawn from the texture at the virtual point it sees (occlusion by the
board exact) - so the tiles whose window straddles the edge see both surfaces at known disparities."""

import numpy as np
import pytest
import torch

from tpnet_gpu import tables
from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.disparity.pairs import AxisSampler
from tpnet_gpu.disparity.two_surface import TwoSurfaceFit, measure_surfaces, neighbourhood_range
from tpnet_gpu.scenes import textures as tx

SIZE, D_FG, D_BG, EDGE = 96, 5.3, 1.2, 52.0  # EDGE: the board's right edge, virtual-camera x (tile 6: half each)


def _edge_frames() -> np.ndarray:
    from scipy import ndimage

    def texture(seed):
        t = tx.noise_texture(np.random.default_rng(seed), 256)[..., 1].astype(np.float64) * 1000.0
        return ndimage.gaussian_filter(t, 0.8, mode="wrap")

    fg_tex, bg_tex = texture(1), texture(2)
    y, x = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    frames = []
    for rx, ry in tables.QUAD_OFFSETS:  # camera i sees virtual point c at c - d r_i: pixel p shows c = p + d r_i
        fx, fy, bx, by = x + D_FG * rx, y + D_FG * ry, x + D_BG * rx, y + D_BG * ry
        fg = ndimage.map_coordinates(fg_tex, [fy + 49.5, fx + 49.5], order=3, mode="wrap")
        bg = ndimage.map_coordinates(bg_tex, [by + 49.5, bx + 49.5], order=3, mode="wrap")
        frames.append(np.where(fx < EDGE, fg, bg))
    return np.array(frames, dtype=np.float32)


@pytest.fixture(scope="module")
def edge_result():
    engine = DisparityEngine(SIZE, SIZE, cfa=None, backend="warp", device="cpu")
    result = engine.run(_edge_frames())
    return result, measure_surfaces(engine, result.disparity)


def test_edge_tiles_get_both_surfaces(edge_result):
    """Tiles whose window is half board, half background (column 6, interior rows): at least 80 % report two
    surfaces, with median errors under 0.4 px for both (the board's edge moves with the foreground, so the
    background's part of the window is cut by a moving mask: measured 0.30 / 0.32 px). Tolerance named here."""
    _, surfaces = edge_result
    fg, bg = surfaces.foreground.numpy()[1:-1, 6], surfaces.background.numpy()[1:-1, 6]
    two = np.isfinite(fg) & np.isfinite(bg)
    assert two.mean() >= 0.8
    assert np.median(np.abs(fg[two] - D_FG)) < 0.4 and np.median(np.abs(bg[two] - D_BG)) < 0.4
    w = surfaces.w_foreground.numpy()[1:-1, 6][two] + surfaces.w_background.numpy()[1:-1, 6][two]
    np.testing.assert_allclose(w, 1.0, atol=1e-5)


def test_single_surface_tiles_report_one(edge_result):
    """Tiles 2+ columns from the edge see one surface: at most 3 % false two-surface reports."""
    _, surfaces = edge_result
    far = np.ones((SIZE // 8, SIZE // 8), dtype=bool)
    far[:, 4:9] = False
    assert np.isfinite(surfaces.foreground.numpy()[far]).mean() <= 0.03


def test_fit_of_two_synthetic_peaks_orders_them():
    """Two Gaussian peaks along the horizontal pairs' axis at residuals +2.5 (stronger) and -1.5: foreground =
    the larger disparity whatever the heights; weights = the heights' shares (within 0.1)."""
    lags = np.arange(-7, 8)
    corr = np.zeros((1, 6, 15, 15))
    vectors = [(1, 0), (1, 0), (0, 1), (0, 1), (1, 1), (1, -1)]
    for p, (vx, vy) in enumerate(vectors):
        for e, h in ((2.5, 1.0), (-1.5, 0.5)):  # a residual e peaks at lag -e v
            corr[0, p] += h * np.exp(-((lags[None] + e * vx) ** 2 + (lags[:, None] + e * vy) ** 2) / 1.5)
    fit = TwoSurfaceFit(AxisSampler(tables.QUAD_OFFSETS, tables.QUAD_PAIRS, torch.device("cpu")))
    found = fit.measure(torch.tensor(corr, dtype=torch.float32))
    assert found.foreground.item() == pytest.approx(2.5, abs=0.1)
    assert found.background.item() == pytest.approx(-1.5, abs=0.1)
    assert found.w_foreground.item() == pytest.approx(1.0 / 1.5, abs=0.1)


def test_neighbourhood_range():
    d = torch.tensor([[1.0, 5.0, float("nan")], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    low, high = neighbourhood_range(d)
    assert (low[1, 1].item(), high[1, 1].item()) == (1.0, 5.0) and high[2, 0].item() == 1.0
