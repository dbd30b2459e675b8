"""Labelled figures (tpnet_gpu/figures.py). Oracles: the matplotlib figure handed to ``savefig`` (its titles, axis
labels, colour-bar label) and the PNG written (Pillow decodes it; its size is WIDTH_IN * DPI per column)."""

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from tpnet_gpu import figures


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
