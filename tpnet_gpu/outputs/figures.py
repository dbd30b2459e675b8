"""Labelled figures of the image outputs (docs/outputs.md §2): matplotlib, drawn on its Agg canvas without pyplot
(no global backend is chosen for the caller's process), imported on first use.

Every figure has a title (the scene, what is shown and the method), axes in pixels (bottom, left) with a second
scale in tiles (top, right: pixel / 8), and for a tile map a colour bar labelled with the quantity and its unit.
Tiles with no value (NaN, and +inf depth) are drawn in ``NO_VALUE`` grey, named in the colour bar's label.
Figures are ``WIDTH_IN`` x (as tall as the picture needs) inches at ``DPI``, with fixed margins (``MARGINS_IN``)
rather than matplotlib's constrained layout, which measures every tick label several times over: it was half of
each figure's ~0.23 s (docs/results.md §11: a VGA one-shot's five figures 1.8 -> 1.1 s).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpnet_gpu.layout import TILE_STRIDE

WIDTH_IN = 6.4  # one panel's width, inches: 640 px at DPI
DPI = 100
NO_VALUE = "0.6"  # grey of tiles without a value (matplotlib's grey level string)
# inches around the panels (left: pixel ticks and label; right: the tile scale of a panel without a colour bar;
# top: the figure's and the panel's titles and the tile scale; bottom: pixel ticks and label) and between them (a
# column: the tile scale, the colour bar's label, the next panel's pixel labels; a row: the bottom and top ones)
MARGINS_IN = {"left": 0.8, "right": 0.55, "top": 1.05, "bottom": 0.65, "column": 1.3, "row": 1.8}


@dataclass(frozen=True)
class Panel:
    """One picture of a figure.

    Attributes:
        values: ``(tiles_y, tiles_x)`` float map (one colour per tile) or ``(H, W, 3|4)`` uint8 image (pixels).
        title: what is shown (the figure's title adds the scene and the method).
        label, unit: the colour bar's quantity and unit (a tile map only), e.g. "disparity", "px".
        cmap: matplotlib colour map name.
        low, high: the colour scale's ends (None: the 1st / 99th percentile of the finite values).
        log: a logarithmic colour scale (depth: near and far tiles both readable), when its ends are positive.
        step: pixels per value of a float map: 8 for a tile map, 1 for a per-pixel map.
    """

    values: np.ndarray
    title: str
    label: str = ""
    unit: str = ""
    cmap: str = "viridis"
    low: float | None = None
    high: float | None = None
    log: bool = False
    step: int = TILE_STRIDE

    @property
    def is_image(self) -> bool:
        return self.values.ndim == 3


def _pixels(panel: Panel, size) -> tuple[int, int]:
    """The panel's extent ``(h, w)`` in pixels: ``size`` (the image's) or its tiles' * 8."""
    if size is not None:
        return size
    if panel.is_image:
        return panel.values.shape[:2]
    return panel.values.shape[0] * panel.step, panel.values.shape[1] * panel.step


def scale(panel: Panel) -> tuple[float, float]:
    """The colour scale's ends of a float map's panel: ``low`` / ``high``, or the finite values' 1st / 99th
    percentiles (so another panel can share them)."""
    finite = panel.values[np.isfinite(panel.values)]
    low = panel.low if panel.low is not None else (float(np.percentile(finite, 1)) if finite.size else 0.0)
    high = panel.high if panel.high is not None else (float(np.percentile(finite, 99)) if finite.size else 1.0)
    return low, (high if high > low else low + 1.0)


def _norm(panel: Panel):
    from matplotlib import colors  # noqa: PLC0415

    low, high = scale(panel)
    if panel.log and low > 0:
        return colors.LogNorm(low, high), True
    return colors.Normalize(low, high), False


def _extend(values: np.ndarray, norm) -> str:
    """The colour bar's arrows: on the side(s) where finite values fall outside the scale."""
    finite = values[np.isfinite(values)]
    low, high = finite.size and finite.min() < norm.vmin, finite.size and finite.max() > norm.vmax
    return {(True, True): "both", (True, False): "min", (False, True): "max"}.get((bool(low), bool(high)), "neither")


def _draw(fig, ax, panel: Panel, size) -> None:
    """One panel on ``ax``: the picture over its pixel extent, the tile scales, the colour bar (tile maps)."""
    from matplotlib import colormaps, ticker  # noqa: PLC0415

    h, w = _pixels(panel, size)
    ax.set_title(panel.title, fontsize=9)
    ax.set_xlabel("x (pixels)")
    ax.set_ylabel("y (pixels)")
    to_tiles = (lambda p: p / TILE_STRIDE, lambda t: t * TILE_STRIDE)
    top = ax.secondary_xaxis("top", functions=to_tiles)
    right = ax.secondary_yaxis("right", functions=to_tiles)
    top.set_xlabel("tile x", fontsize=8)
    right.set_ylabel("tile y", fontsize=8)
    top.xaxis.set_major_locator(ticker.MaxNLocator("auto", integer=True))  # "auto": as many as the length fits
    right.yaxis.set_major_locator(ticker.MaxNLocator("auto", integer=True))
    if panel.is_image:
        ax.imshow(panel.values, extent=(0, panel.values.shape[1], panel.values.shape[0], 0), interpolation="nearest")
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        return
    values = np.ma.masked_invalid(np.asarray(panel.values, dtype=np.float64))
    cmap = colormaps[panel.cmap].with_extremes(bad=NO_VALUE)
    norm, log = _norm(panel)
    ty, tx = values.shape
    image = ax.imshow(values, cmap=cmap, norm=norm, extent=(0, tx * panel.step, ty * panel.step, 0),
                      interpolation="nearest")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    bar = fig.colorbar(image, ax=ax, shrink=0.8, pad=0.12, extend=_extend(values.filled(np.nan), norm))
    if log:  # plain numbers (50, 100, 200) rather than powers of ten
        bar.ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        bar.ax.yaxis.set_minor_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
    scale = ", log scale" if log else ""
    missing = ", grey: none or infinite" if values.mask.any() else ""
    bar.set_label(f"{panel.label} ({panel.unit}{scale}){missing}", fontsize=8)


def _margins(width: float, height: float, rows: int, columns: int) -> dict:
    """``GridSpec`` keywords placing ``rows`` x ``columns`` panels in a ``width`` x ``height`` inch figure with
    ``MARGINS_IN`` around and between them."""
    m = MARGINS_IN
    inner_w = width - m["left"] - m["right"]
    inner_h = height - m["top"] - m["bottom"]
    panel_w = (inner_w - (columns - 1) * m["column"]) / columns
    panel_h = (inner_h - (rows - 1) * m["row"]) / rows
    return {"left": m["left"] / width, "right": 1 - m["right"] / width, "bottom": m["bottom"] / height,
            "top": 1 - m["top"] / height, "wspace": m["column"] / panel_w, "hspace": m["row"] / panel_h}


def save(path, panels, *, title: str, size=None, columns: int | None = None) -> Path:
    """Draw ``panels`` (a ``Panel`` or a list of them, ``columns`` per row, default all in one row) under the
    figure title ``title`` and write it as a PNG of ``WIDTH_IN * columns`` inches at ``DPI``. ``size``: the image
    ``(h, w)`` in pixels the tile maps cover (default: their tiles * 8)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415 - on use (slow import)
    from matplotlib.figure import Figure  # noqa: PLC0415

    panels = [panels] if isinstance(panels, Panel) else list(panels)
    if not panels:
        raise ValueError("panels: expected at least one panel, got none")
    columns = columns or len(panels)
    rows = -(-len(panels) // columns)
    h, w = _pixels(panels[0], size)
    # each row: the picture (its aspect at 0.8 of the panel's width) and 0.3 in; the margins around and between
    picture = WIDTH_IN * 0.8 * h / w + 0.3
    m = MARGINS_IN
    width, height = WIDTH_IN * columns, m["top"] + m["bottom"] + rows * picture + (rows - 1) * m["row"]
    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.suptitle(title, fontsize=11, y=1 - 0.12 / height)
    axes = fig.subplots(rows, columns, squeeze=False, gridspec_kw=_margins(width, height, rows, columns)).ravel()
    for ax, panel in zip(axes, panels):
        _draw(fig, ax, panel, size)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    path = Path(path)
    fig.savefig(path, dpi=DPI, format="png")
    return path



def save_correlations(path, corr: np.ndarray, tiles: list[tuple[int, int]], pairs, *, title: str) -> Path:
    """The pair correlations of a few tiles as a labelled grid: ``corr`` ``(len(tiles), pairs, 15, 15)`` (row:
    tile ``(ty, tx)`` of ``tiles``, column: camera pair of ``pairs``), each drawn over its lags in px (x right,
    y down) on one shared colour scale with its colour bar (correlation, unitless)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415 - on use (slow import)
    from matplotlib.figure import Figure  # noqa: PLC0415

    corr = np.asarray(corr, dtype=np.float64)
    if corr.ndim != 4 or corr.shape[:2] != (len(tiles), len(pairs)) or corr.shape[2] != corr.shape[3]:
        raise ValueError(f"corr: expected shape ({len(tiles)}, {len(pairs)}, n, n), got {corr.shape}")
    reach = corr.shape[-1] // 2
    rows, columns = corr.shape[:2]
    fig = Figure(figsize=(1.6 * columns + 1.2, 1.6 * rows + 0.8), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(title, fontsize=11)
    axes = fig.subplots(rows, columns, squeeze=False)
    extent = (-reach - 0.5, reach + 0.5, reach + 0.5, -reach - 0.5)  # each cell centred on its whole-pixel lag
    low, high = float(np.nanmin(corr)), float(np.nanmax(corr))
    for r, (ty, tx) in enumerate(tiles):
        for c, (a, b) in enumerate(pairs):
            ax = axes[r, c]
            image = ax.imshow(corr[r, c], cmap="magma", vmin=low, vmax=high, extent=extent, interpolation="nearest")
            ax.tick_params(labelsize=6)
            if r == 0:
                ax.set_title(f"cameras {a}-{b}", fontsize=8)
            if c == 0:
                ax.set_ylabel(f"tile ({ty}, {tx})\nlag y (px)", fontsize=7)
            if r == rows - 1:
                ax.set_xlabel("lag x (px)", fontsize=7)
    fig.colorbar(image, ax=axes, shrink=0.8).set_label("correlation (unitless)", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=DPI, format="png")
    return path
