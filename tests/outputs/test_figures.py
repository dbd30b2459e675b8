"""Labelled figures (tpnet_gpu/outputs/figures.py). Oracles: the matplotlib figure handed to ``savefig`` (its titles, axis
labels, colour-bar label) and the PNG written (Pillow decodes it; its size is WIDTH_IN * DPI per column)."""

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from tpnet_gpu.outputs import figures


@pytest.fixture
def drawn(monkeypatch):
    """The figures ``figures.save`` draws, as they are saved."""
    seen = []
    save = Figure.savefig

    def spy(self, *args, **kwargs):
        seen.append(self)
        return save(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", spy)
    return seen


def test_a_tile_map_figure_has_title_pixel_and_tile_axes_and_a_colour_bar_with_units(tmp_path, drawn):
    values = np.linspace(0.5, 12, 15 * 20).reshape(15, 20)
    values[0, 0] = np.nan
    panel = figures.Panel(values, "disparity: TPNET", "disparity", "px", "turbo")
    path = figures.save(tmp_path / "d.png", panel, title="scene demo-0", size=(120, 160))
    (fig,) = drawn
    assert fig._suptitle.get_text() == "scene demo-0"
    main, bar = fig.axes[0], fig.axes[-1]
    assert main.get_title() == "disparity: TPNET"
    assert (main.get_xlabel(), main.get_ylabel()) == ("x (pixels)", "y (pixels)")
    assert main.get_xlim() == (0.0, 160.0) and main.get_ylim() == (120.0, 0.0)  # pixels, y down
    labels = {ax.get_xlabel() for ax in main.child_axes} | {ax.get_ylabel() for ax in main.child_axes}
    assert {"tile x", "tile y"} <= labels
    assert bar.get_ylabel() == "disparity (px), grey: none or infinite"
    with Image.open(path) as image:
        image.load()
        assert image.size[0] == figures.WIDTH_IN * figures.DPI


def test_depth_gets_a_log_scale_and_images_no_colour_bar(tmp_path, drawn):
    depth = np.geomspace(20, 900, 12).reshape(3, 4)
    rgb = np.zeros((24, 32, 3), dtype=np.uint8)
    figures.save(tmp_path / "c.png", [figures.Panel(depth, "depth", "depth Z", "m", log=True), figures.Panel(rgb, "texture")],
                 title="t", columns=2)
    (fig,) = drawn
    assert any(ax.get_ylabel() == "depth Z (m, log scale)" for ax in fig.axes)
    assert sum("(" in ax.get_ylabel() and ax.get_ylabel() != "y (pixels)" for ax in fig.axes) == 1
    with Image.open(tmp_path / "c.png") as image:
        assert image.size[0] == 2 * figures.WIDTH_IN * figures.DPI
    with pytest.raises(ValueError, match="panels: expected at least one panel"):
        figures.save(tmp_path / "e.png", [], title="t")


def test_correlation_grid_draws_each_cell_at_its_lags_with_labels(tmp_path, drawn):
    """Oracle: a correlation with a single peak at lag (y, x) = (2, -3) px must be drawn at that lag (the image's
    extent maps whole-pixel lags to cell centres), with the pairs, tiles, lag axes and a unit on the colour bar."""
    corr = np.zeros((2, 3, 15, 15))
    corr[1, 2, 7 + 2, 7 - 3] = 1.0
    figures.save_correlations(tmp_path / "c.png", corr, [(4, 5), (6, 7)], [(0, 1), (2, 3), (0, 2)], title="scene s")
    (fig,) = drawn
    grid = fig.axes[:6]
    assert [ax.get_title() for ax in grid[:3]] == ["cameras 0-1", "cameras 2-3", "cameras 0-2"]
    assert grid[3].get_ylabel().startswith("tile (6, 7)") and grid[5].get_xlabel() == "lag x (px)"
    assert fig.axes[-1].get_ylabel() == "correlation (unitless)"
    image = grid[5].images[0]
    left, right, bottom, top = image.get_extent()  # imshow's upper origin: array row 0 at ``top``
    row, col = np.unravel_index(np.argmax(image.get_array()), image.get_array().shape)
    drawn_at = (left + (col + 0.5) * (right - left) / 15, top + (row + 0.5) * (bottom - top) / 15)
    assert drawn_at == pytest.approx((-3.0, 2.0))
    with pytest.raises(ValueError, match="corr: expected shape"):
        figures.save_correlations(tmp_path / "d.png", corr[:1], [(4, 5), (6, 7)], [(0, 1)] * 3, title="s")
