"""The Taichi backend of ``TileProcessor``: the launches of kernels/taichi_*.py on the processor's own buffers.

The processor owns every buffer (Warp arrays); this class holds zero-copy torch views of them, which Taichi takes
as ``ti.types.ndarray`` arguments (bool masks as uint8 views), plus the few tables only the Taichi kernels use,
all built from ``tpnet_gpu.tables``. Imported only when a processor is built with ``backend="taichi"``.
"""

from __future__ import annotations

import numpy as np
import torch
import warp as wp

from tpnet_gpu import taichi_setup, tables
from tpnet_gpu.kernels import taichi_convert, taichi_correlate, taichi_frames, taichi_texture


def _u8(a: wp.array) -> torch.Tensor:
    return wp.to_torch(a).view(torch.uint8)


class TaichiLaunches:
    """Views of ``tp``'s buffers and the Taichi launches of its stages (the caller serialises them)."""

    def __init__(self, tp):
        self.tp = tp
        self.arch = "cuda" if tp.device.is_cuda else "cpu"
        taichi_setup.init_taichi(self.arch)
        t = wp.to_torch

        def table(data, dtype=torch.float32) -> torch.Tensor:
            return torch.tensor(np.ascontiguousarray(data), dtype=dtype, device=tp.torch_device)

        # the inverse transform as 8-point DCT-II/DST-II products + a signed gather into the (2r+1)^2 lags
        unfold = [tables.unfold_matrix(sine, tables.CORR_RADIUS) for sine in (False, True)]
        self.padded, self.disparity, self.offsets = t(tp._padded), tp._disparity_t, t(tp._offsets)
        self.centres, self.active, self.all_active = tp._centres_t, _u8(tp._active), _u8(tp._all_active)
        self.masks, self.kernels, self.clt = t(tp._masks), t(tp._kernels), t(tp._clt)
        self.finite, self.valid, self.corr = _u8(tp._finite), _u8(tp._valid), t(tp._corr)
        self.layers = None if tp._layers is None else t(tp._layers)
        self.pairs, self.colour_weights = t(tp._pairs), t(tp._colour_weights)
        self.lpf_rb, self.lpf_corr = t(tp._lpf_rb), t(tp._lpf_corr)
        self.dtt2e = table(np.stack([0.5 * tables.dtt2e_matrix(sine) for sine in (False, True)]))  # (2, 8, 8)
        self.unfold_index = table(np.stack([np.abs(u).argmax(axis=1) for u in unfold]), torch.int32)  # (2, 15)
        self.unfold_sign = table(np.stack([u.sum(axis=1) for u in unfold]))  # (2, 15)
        if tp.textures:
            self.pix, self.cmp, self.weights = t(tp._tex_pix), t(tp._tex_cmp), t(tp._tex_weights)
            self.canvas, self.tex_lpf = tp._canvas_t, t(tp._tex_lpf)
            self.inv_cos, self.inv_sin = t(tp._inv_cos), t(tp._inv_sin)
            self.tex_weights_c, self.channel_of_colour = t(tp._tex_weights_c), t(tp._channel_of_colour)
            window = tables.half_sine(np.arange(tables.TILE_SIZE)) ** 2
            self.window2 = table(np.outer(window, window))  # (16, 16) squared 2D window

    def prepare(self, frames: torch.Tensor, ideal: bool) -> None:
        """Tile centres from the target disparities (``ideal``; else the given centres stay) and the padding."""
        if ideal:
            taichi_frames.ideal_tile_centres(self.disparity, self.offsets, self.centres)
        taichi_frames.pad_frames(frames, self.padded)

    def convert(self, every_tile: bool) -> None:
        tp = self.tp
        taichi_convert.convert_tiles(
            self.padded, self.centres, self.all_active if every_tile else self.active, self.masks, self.kernels,
            tp._kernel_grid[0], tp._kernel_grid[1], int(tp._use_kernels), tp.height, tp.width, tp.colours,
            self.clt, self.finite, self.valid,
        )

    def correlate(self) -> None:
        tp, cfg = self.tp, self.tp.config
        taichi_correlate.correlate_tiles(
            self.clt, self.finite, self.pairs, tp.cams, tp.colours, self.colour_weights, cfg.fat_zero, self.lpf_rb,
            self.lpf_corr, self.dtt2e, self.unfold_index, self.unfold_sign, self.corr,
        )
        if self.layers is not None:
            taichi_correlate.network_layers(self.corr, cfg.net_offset, self.layers)

    def texture(self) -> None:
        tp, tc = self.tp, self.tp.texture_config
        taichi_texture.clear_canvas(self.canvas)
        taichi_texture.texture_imclt(self.clt, self.finite, tp.cams, tp.colours, self.tex_lpf, self.inv_cos,
                                     self.inv_sin, self.pix)
        taichi_texture.texture_demosaic(self.pix, self.finite, tp.cams, tp.colours, tc.scale_shot, tc.min_shot,
                                        self.window2, self.cmp)
        taichi_texture.texture_combine(
            self.pix, self.cmp, self.finite, tp.tiles_x, tp.tiles_y, tp.cams, tp.colours, self.offsets,
            self.tex_weights_c, self.channel_of_colour, tc.diff_sigma, tables.TEXTURE_WEIGHT_FLOOR,
            int(tc.dust_remove), tc.output_gain, self.window2, self.weights, self.canvas,
        )
