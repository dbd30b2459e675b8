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


@pytest.fixture
def texts(monkeypatch):
    """The texts matplotlib draws (titles, tick labels in view, axis and colour-bar labels), as it draws them."""
    from matplotlib.text import Text

    seen = {}
    draw = Text.draw

    def spy(self, renderer):
        if self.get_visible() and self.get_text().strip():
            seen[id(self)] = self
        return draw(self, renderer)

    monkeypatch.setattr(Text, "draw", spy)
    return seen


def _overlap(a, b) -> float:
    """Pixels two display boxes overlap by (the lesser of the two axes; <= 0: apart)."""
    return min(min(a.x1, b.x1) - max(a.x0, b.x0), min(a.y1, b.y1) - max(a.y0, b.y0))


@pytest.mark.parametrize("size, columns, image_last", [((370, 463), 1, False), ((370, 463), 1, True),
                                                       ((900, 300), 1, False), ((120, 960), 1, False),
                                                       ((370, 463), 3, True), ((64, 960), 1, None)])
def test_every_label_lies_inside_the_figure_and_off_the_other_panels(tmp_path, drawn, texts, size, columns,
                                                                      image_last):
    """Oracle: the renderer's own extents of every drawn text - inside the canvas (fixed margins, no layout engine
    to move them), not over another panel's picture nor over another text. Tile maps with colour bars and the
    texture image; landscape, portrait and a wide strip; one panel per figure (``tpnet process``'s) and the demo's
    3-column grid; five rows of a thin strip (``image_last`` None). Tolerance 0.5 px (the extents are in fractional
    pixels)."""
    h, w = size
    tiles = np.linspace(0.5, 150, (h // 8) * (w // 8)).reshape(h // 8, w // 8)
    panels = [figures.Panel(tiles, "disparity: engine", "disparity", "px", "turbo"),
              figures.Panel(tiles, "depth: engine", "depth Z", "m", "turbo_r", log=True),
              figures.Panel(np.abs(tiles - 3), "|error|: engine", "|disparity - ground truth|", "px", "inferno", 0, 1)]
    image = figures.Panel(np.zeros((h, w, 3), dtype=np.uint8), "texture at the final disparity")
    if image_last is None:
        panels = panels[:1] * 5
    else:
        panels = ([image] if image_last else panels[:1]) if columns == 1 else panels + panels[:2] + [image]
    figures.save(tmp_path / "f.png", panels, title="scene s: ground truth vs engine", size=size, columns=columns)
    (fig,) = drawn
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    boxes = [(text, text.get_window_extent(renderer)) for text in texts.values()]
    pictures = [ax for ax in fig.axes if ax.images and ax.get_label() != "<colorbar>"]
    for text, box in boxes:
        assert canvas.x0 - 0.5 <= box.x0 and box.x1 <= canvas.x1 + 0.5, (text.get_text(), box, canvas)
        assert canvas.y0 - 0.5 <= box.y0 and box.y1 <= canvas.y1 + 0.5, (text.get_text(), box, canvas)
        for ax in pictures:  # its own titles and scales sit around it; any other text must stay off it
            if not any(text in a.findobj(type(text)) for a in (ax, *ax.child_axes)):
                assert _overlap(box, ax.get_window_extent(renderer)) <= 0.5, (text.get_text(), box)
    for i, (text, box) in enumerate(boxes):  # nor on one another (a colour bar's label on the next panel's ticks)
        for other, near in boxes[i + 1:]:
            assert _overlap(box, near) <= 0.5, (text.get_text(), other.get_text())


def test_rows_of_a_strip_too_thin_for_labels_still_save(tmp_path):
    """Five rows of a 16x960 picture: the fixed margins leave each row its picture's height (a figure whose
    margins exceeded its height raised "bottom cannot be >= top" before)."""
    tiles = np.linspace(0.5, 150, 2 * 120).reshape(2, 120)
    panel = figures.Panel(tiles, "disparity: engine", "disparity", "px", "turbo")
    path = figures.save(tmp_path / "s.png", [panel] * 5, title="s", size=(16, 960), columns=1)
    with Image.open(path) as image:
        assert image.size[0] == figures.WIDTH_IN * figures.DPI
