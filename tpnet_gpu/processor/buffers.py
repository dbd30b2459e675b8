"""Every device array of a tile processor and its zero-copy torch view, allocated once (tile_processor.md §1).

``Buffers`` owns the per-frame buffers (staging, padded frames, targets, CLT tiles, correlations, layers,
textures) and the constant tables the kernels read, all uploaded from ``tpnet_gpu.operators``/``tables``. Both
backends work on these arrays: Warp through the ``wp.array``s, Taichi through the torch views (bool masks as
uint8 views). ``TileResult`` is the set of output views a processor returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from tpnet_gpu import operators, tables
from tpnet_gpu.config import CorrelationConfig, TextureConfig
from tpnet_gpu.layout import CORR_RADIUS, CORR_SIDE, DTT_SIZE, NET_LAYERS, NET_SIDE, PAD, TILE_SIZE, TILE_STRIDE
from tpnet_gpu.processor.validate import Geometry


@dataclass(frozen=True)
class TileResult:
    """Outputs of one ``TileProcessor`` pass (views of the processor's buffers, overwritten by the next pass).

    Attributes:
        clt: ``(tiles, cams, colours, 4, 8, 8)`` frequency-domain tiles (CC, SC, CS, SS; colours R, B, G).
            Stale for inactive tiles, zero-filled windows where pixels were not finite. None unless the
            processor has the buffer (built with ``clt=True`` or ``textures=True``); after a ``measure`` they
            are this pass's tiles only with ``clt=True`` (otherwise the fused pass does not write them).
        corr: ``(tiles, pairs, 15, 15)`` pair correlations, row = vertical lag + 7; zero where not computed.
        layers: ``(tiles, 4, 9, 9)`` network layers [hor, vert, diag-main, diag-other], or None unless the
            pairs are the quad's 6.
        valid: ``(tiles,)`` bool: active, every centre and window pixel finite (pixels also at most
            ``layout.PIXEL_LIMIT`` = 2^50 in magnitude), every window wholly inside the image and none of them
            featureless (all its pixels equal: tile_processor.md §1.4, §6.7). Tiles with windows partly off the image still get values computed from pair-clamped
            pixels; tiles with non-finite input or inactive tiles get zero correlations.
        finite: ``(tiles,)`` bool: active, every centre and window pixel finite (``valid`` without the
            inside-the-image and featureless conditions: the tile's windows hold data).
        centres: ``(tiles, cams, 2)`` the per-camera tile centres (x, y) used, pixels.
        texture: ``(4, H, W)`` R, G, B, alpha (mono: ``(2, H, W)`` Y, alpha) overlap-added textures of the
            tiles with finite input, or None unless the processor was built with ``textures=True``. Colours are
            x ``output_gain`` (raw units); alpha ~1 where the cameras agree, ~0 where they do not or where no
            tile contributed (an empty texture is all zero).
    """

    clt: torch.Tensor | None
    corr: torch.Tensor
    layers: torch.Tensor | None
    valid: torch.Tensor
    finite: torch.Tensor
    centres: torch.Tensor
    texture: torch.Tensor | None


# Tile rows of one texture band: the texture's per-camera scratch is 1 KiB per tile, camera and colour (pix and
# cmp) - 1.9 GB for a 5 MPix quad frame at once, 61 MiB per band of 8 rows. A texturing processor without
# ``clt=True`` also converts band by band into a band of CLT tiles (30 MiB instead of 0.9 GiB at 5 MPix) and
# keeps the RGBA contributions of ``ring_rows`` tile rows (the band and the row above it, which the overlap-add
# of the band's first canvas rows reads): 12 MiB instead of 306 MiB. (16 rows: 110 MiB more at 5 MPix.)
TEXTURE_BAND_ROWS = 8


def texture_band_tiles(tiles_y: int, tiles_x: int) -> int:
    """Tiles the texture scratch holds: one band."""
    return min(TEXTURE_BAND_ROWS, tiles_y) * tiles_x


def texture_ring_rows(tiles_y: int) -> int:
    """Tile rows of RGBA contributions kept: one band and the row before it (all rows of a shorter frame)."""
    return min(TEXTURE_BAND_ROWS + 1, tiles_y)


@dataclass(frozen=True)
class TextureBand:
    """Views of one band of tile rows ``[first, last)`` for the texture steps (all contiguous, made once).

    ``clt``: the band's CLT tiles (in the whole-frame buffer, or the band buffer it is converted into);
    ``centres``, ``active``, ``all_active``, ``finite``, ``valid``: the band's tiles of the whole-frame arrays
    (what a band's convert reads and writes); ``pix``, ``cmp``, ``weights``: their slots in the scratch. The
    combine step reads the whole frame's ``finite`` (the neighbours' for the alpha fade) and writes the band's
    tiles into the ``tex_rgba`` ring (row ``ty`` in slot row ``ty % ring_rows``); the overlap-add then writes
    canvas rows ``[y0, y0 + rows)``, which read tile rows ``first - 1`` to ``last - 1`` only."""

    first: int
    last: int
    clt: wp.array
    centres: wp.array
    active: wp.array
    all_active: wp.array
    finite: wp.array
    valid: wp.array
    pix: wp.array
    cmp: wp.array
    weights: wp.array
    y0: int
    rows: int


class Buffers:
    """Device arrays of one processor (Warp) with their torch views; see the module docstring.

    Per-frame arrays (shapes): ``frames`` (cams, H, W) input staging; ``padded`` (cams, H + 2 PAD, W + 2 PAD);
    ``disparity`` (tiles_y, tiles_x); ``centres`` (tiles, cams, 2); ``active``, ``all_active``, ``finite``,
    ``valid`` (tiles,) bool; ``clt`` (tiles * cams * colours * 4, 8, 8) or None (``keep_clt`` False); ``corr``
    (tiles * pairs, 15, 15); ``layers`` (tiles, 4, 9, 9) or None; the fused pass's ``tasks`` (tiles,) int32,
    ``count`` (1,) int32, ``written`` and ``layers_written`` (tiles,) bool and ``scratch`` (slots * cams * U * 4,
    8, 8) (``allocate_fused``; U: the used colours).
    Texture (``textures=True``): ``tex_rgba`` (ring_rows * tiles_x * (colours + 1), 16, 16) per-tile
    contributions of ``texture_ring_rows`` tile rows, ``canvas`` (colours + 1, H + 8, W + 8), the scratch of one
    band of ``TEXTURE_BAND_ROWS`` tile rows (span = ``texture_band_tiles``): ``tex_pix``, ``tex_cmp`` (span * cams
    * colours, 16, 16), ``tex_weights`` (span * cams, 16, 16, Warp only); ``band_clt`` (span * cams * colours * 4,
    8, 8) the band's CLT tiles, or None where the whole-frame ``clt`` is kept (the bands read it);
    ``texture_bands`` the views of each band (``TextureBand``).
    """

    def __init__(self, geo: Geometry, config: CorrelationConfig, texture_config: TextureConfig | None,
                 kernels: np.ndarray | None, device: wp.Device, *, keep_clt: bool):
        self.device, self.geo = device, geo
        self.torch_device = torch.device(wp.device_to_torch(device))
        cams, tiles, colours, npairs = geo.cams, geo.tiles, geo.colours, len(geo.pairs)
        zeros = self._zeros
        self.frames = zeros((cams, geo.height, geo.width))
        self.padded = zeros((cams, geo.height + 2 * PAD, geo.width + 2 * PAD))
        self.disparity = zeros((geo.tiles_y, geo.tiles_x))
        self.active = wp.ones(tiles, dtype=wp.bool, device=device)
        self.all_active = wp.ones(tiles, dtype=wp.bool, device=device)
        self.centres = zeros((tiles, cams, 2))
        self.clt = zeros((tiles * cams * colours * 4, DTT_SIZE, DTT_SIZE)) if keep_clt else None  # ~1 GB at 5 MPix
        self.finite = wp.zeros(tiles, dtype=wp.bool, device=device)
        self.valid = wp.zeros(tiles, dtype=wp.bool, device=device)
        self.corr = zeros((tiles * npairs, CORR_SIDE, CORR_SIDE))
        self.layers = zeros((tiles, NET_LAYERS, NET_SIDE, NET_SIDE)) if geo.pairs == tables.QUAD_PAIRS else None
        self.tasks = wp.zeros(tiles, dtype=wp.int32, device=device)
        self.count = wp.zeros(1, dtype=wp.int32, device=device)
        # tiles whose correlations (layers) an earlier pass may have left non-zero: the fused pass clears only
        # those of its inactive tiles, so a sparse pass costs its share of the tiles
        self.written = wp.zeros(tiles, dtype=wp.bool, device=device)
        self.layers_written = wp.zeros(tiles, dtype=wp.bool, device=device)
        self.scratch = None
        self._tables(geo, config, kernels)
        texture_view = None if texture_config is None else self._texture(geo, texture_config)
        t = wp.to_torch
        self.result = TileResult(
            clt=None if self.clt is None else t(self.clt).view(tiles, cams, colours, 4, DTT_SIZE, DTT_SIZE),
            corr=t(self.corr).view(tiles, npairs, CORR_SIDE, CORR_SIDE),
            layers=None if self.layers is None else t(self.layers),
            valid=t(self.valid),
            finite=t(self.finite),
            centres=t(self.centres),
            texture=texture_view,
        )
        self.frames_t, self.disparity_t, self.active_t = t(self.frames), t(self.disparity), t(self.active)

    def allocate_fused(self, slots: int) -> None:
        """The fused pass's scratch for ``slots`` workers (the backend's choice): ``(slots * cams * U * 4, 8, 8)``."""
        used = self.used_colours.shape[0]
        self.scratch = self._zeros((slots * self.geo.cams * used * 4, DTT_SIZE, DTT_SIZE))

    # --- helpers ---------------------------------------------------------------------------------------------
    def _zeros(self, shape) -> wp.array:
        return wp.zeros(shape, dtype=wp.float32, device=self.device)

    def upload(self, data, dtype=wp.float32) -> wp.array:
        """A constant table on the device (float64 host tables become float32)."""
        host = np.ascontiguousarray(data, dtype=np.int32 if dtype == wp.int32 else np.float32)
        return wp.array(host, dtype=dtype, device=self.device)

    def torch(self, array: wp.array) -> torch.Tensor:
        """Zero-copy torch view of one of these arrays (bool as uint8, as Taichi takes masks)."""
        view = wp.to_torch(array, requires_grad=False)
        return view.view(torch.uint8) if view.dtype == torch.bool else view

    # --- constant tables ---------------------------------------------------------------------------------------
    def _tables(self, geo: Geometry, cfg: CorrelationConfig, kernels: np.ndarray | None) -> None:
        up = self.upload
        self.offsets = wp.array(geo.offsets, dtype=wp.vec2f, device=self.device)  # (cams,) vec2
        self.pairs = up(np.array(geo.pairs), wp.int32)  # (pairs, 2)
        masks = operators.colour_masks(geo.cfa).reshape(-1, TILE_SIZE, TILE_SIZE)
        # The Taichi kernels read a row's weights from its first two columns: masks must repeat every 2 columns.
        assert np.array_equal(masks, np.roll(masks, 2, axis=-1)), "colour masks must be 2-periodic along rows"
        self.masks = up(masks)  # (4 colours, 16, 16)
        self.use_kernels = kernels is not None
        k = kernels if kernels is not None else np.zeros((1, 1, 1, 1, 4, DTT_SIZE, DTT_SIZE), np.float32)
        self.kernel_grid = (k.shape[1], k.shape[2])  # (rows, cols) of the 16-px kernel grid
        self.kernels = up(k.reshape(-1, DTT_SIZE, DTT_SIZE))
        # Index tables of the Warp convert kernel's closed-form bases: k (rows) and n (columns) as tiles.
        k_index, n_index = np.arange(DTT_SIZE), np.arange(TILE_SIZE)
        self.k_rows = up(np.broadcast_to(k_index[:, None], (DTT_SIZE, TILE_SIZE)))
        self.n_rows = up(np.broadcast_to(n_index[None, :], (DTT_SIZE, TILE_SIZE)))
        self.n_cols = up(np.broadcast_to(n_index[:, None], (TILE_SIZE, DTT_SIZE)))
        self.k_cols = up(np.broadcast_to(k_index[None, :], (TILE_SIZE, DTT_SIZE)))
        self.colour_weights = up(cfg.colour_weights)  # (colours,)
        self.lpf_rb, self.lpf_corr = up(tables.lpf(cfg.sigma_rb)), up(tables.lpf(cfg.sigma_corr))  # (8, 8)
        lags = operators.lag_operators(CORR_RADIUS)  # (2, 15, 8)
        self.lags_cos, self.lags_sin = up(lags[0]), up(lags[1])
        self.freqs_cos, self.freqs_sin = up(lags[0].T), up(lags[1].T)  # (8, 15)
        # The colours a correlation reads: those of non-zero weight (all of them when every weight is zero).
        weights = np.asarray(cfg.colour_weights, dtype=np.float64)
        used = np.flatnonzero(weights) if weights.any() else np.arange(geo.colours)
        self.used_colours, self.used_weights = up(used, wp.int32), up(weights[used])  # (U,)
        self.used_positions = up(np.arange(len(used)), wp.int32)  # (U,): their places in the fused scratch
        self.all_colours = up(np.arange(geo.colours), wp.int32)  # (colours,): what the split convert writes
        # Taichi: the lag unfold as a gather (2, 15) (the forward basis' shift-free parts are compile-time there).
        index, sign = operators.unfold_gather(CORR_RADIUS)
        self.unfold_index, self.unfold_sign = up(index, wp.int32), up(sign)

    def _texture(self, geo: Geometry, tc: TextureConfig) -> torch.Tensor:
        """Texture buffers and tables; returns the image view ``(colours + 1, H, W)`` of the canvas."""
        side = (TILE_SIZE, TILE_SIZE)
        span = texture_band_tiles(geo.tiles_y, geo.tiles_x)
        channels = geo.colours + 1
        self.ring_rows = texture_ring_rows(geo.tiles_y)
        self.band_clt = self._zeros((span * geo.cams * geo.colours * 4, DTT_SIZE, DTT_SIZE)) if self.clt is None \
            else None
        self.tex_pix = self._zeros((span * geo.cams * geo.colours, *side))
        self.tex_cmp = self._zeros((span * geo.cams * geo.colours, *side))
        self.tex_weights = self._zeros((span * geo.cams, *side))
        self.tex_rgba = self._zeros((self.ring_rows * geo.tiles_x * channels, *side))
        margin = TILE_STRIDE // 2  # tile (0, 0)'s window starts 4 px before the frame
        self.canvas = self._zeros((geo.colours + 1, self.canvas_rows(geo), geo.width + 2 * margin))
        self.texture_bands = [self._band(geo, first, min(first + TEXTURE_BAND_ROWS, geo.tiles_y))
                              for first in range(0, geo.tiles_y, TEXTURE_BAND_ROWS)]
        up = self.upload
        self.tex_lpf = up(np.stack([tables.lpf(s) for s in tc.lpf_sigmas]))  # (colours, 8, 8)
        inverse = operators.inverse_axes()  # (2, 16, 8)
        self.inv_cos, self.inv_sin = up(inverse[0]), up(inverse[1])
        self.inv_cos_t, self.inv_sin_t = up(inverse[0].T), up(inverse[1].T)
        self.window2 = up(operators.window_squared())  # (16, 16)
        self.inv_window2 = up(1.0 / operators.window_squared())  # (16, 16), the demosaic multiplies
        self.tex_weights_c = up(tc.colour_weights)  # (colours,)
        # Output channels in R, G, B order (internal colour order is R, B, G).
        self.channel_of_colour = up([0, 2, 1] if geo.colours == 3 else [0], wp.int32)
        self.canvas_t = wp.to_torch(self.canvas)
        return self.canvas_t[:, margin : margin + geo.height, margin : margin + geo.width]

    def _band(self, geo: Geometry, first: int, last: int) -> TextureBand:
        """The views of tile rows ``[first, last)``."""
        per_tile = geo.cams * geo.colours
        start, inner = first * geo.tiles_x, (last - first) * geo.tiles_x  # tiles
        tiles = slice(start, start + inner)
        clt = self.band_clt[: inner * per_tile * 4] if self.clt is None else \
            self.clt[start * per_tile * 4 : (start + inner) * per_tile * 4]
        # canvas row y reads tile rows y // 8 - 1 and y // 8: rows [8 first, 8 last) need rows first - 1 .. last - 1
        end = self.canvas_rows(geo) if last == geo.tiles_y else TILE_STRIDE * last
        return TextureBand(
            first=first, last=last, clt=clt, centres=self.centres[tiles], active=self.active[tiles],
            all_active=self.all_active[tiles], finite=self.finite[tiles], valid=self.valid[tiles],
            pix=self.tex_pix[: inner * per_tile], cmp=self.tex_cmp[: inner * per_tile],
            weights=self.tex_weights[: inner * geo.cams], y0=TILE_STRIDE * first, rows=end - TILE_STRIDE * first,
        )

    @staticmethod
    def canvas_rows(geo: Geometry) -> int:
        """Rows of the canvas: the frame and a half tile stride each side."""
        return geo.height + TILE_STRIDE
