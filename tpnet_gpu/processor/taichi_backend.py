"""The Taichi backend: launches of kernels/taichi_*.py over ``Buffers``, spread over every CPU core.

The kernels read and write the processor's own arrays through zero-copy torch views (``ti.types.ndarray``;
bool masks as uint8 views), so results, layouts and tables are those of the Warp backend. Taichi has one runtime
per process (arch, threads, compiled kernels): launches are serialised, the processor's arch is made current,
and on CUDA the kernels wait for torch's stream before and Taichi is synchronised after. Imported only when a
processor is built with ``backend="taichi"``.
"""

from __future__ import annotations

import threading

import torch

from tpnet_gpu import tables
from tpnet_gpu.runtime import taichi_setup
from tpnet_gpu.config import CorrelationConfig, TextureConfig
from tpnet_gpu.kernels import taichi_convert, taichi_correlate, taichi_frames, taichi_fused, taichi_texture
from tpnet_gpu.layout import CPU_FUSED_SLOTS_PER_THREAD, CUDA_FUSED_SLOTS, NET_LAYERS, NET_SIDE
from tpnet_gpu.processor.backend import run_bands
from tpnet_gpu.processor.buffers import Buffers
from tpnet_gpu.processor.validate import Geometry

_TAICHI_LOCK = threading.Lock()


class TaichiBackend:
    """Taichi launches of one processor's steps (see the module docstring)."""

    name = "taichi"

    def __init__(self, geo: Geometry, config: CorrelationConfig, texture_config: TextureConfig | None,
                 buffers: Buffers):
        self.geo, self.config, self.texture_config, self.b = geo, config, texture_config, buffers
        self.cuda = buffers.device.is_cuda
        self.arch = "cuda" if self.cuda else "cpu"
        taichi_setup.init_taichi(self.arch)
        self.t = {}  # Warp array id (or ("runs", id)) -> its torch view, made once
        self.packs: dict | None = None  # the argument packs, during a run (``_argpacks``)
        self.frames_t = buffers.frames_t
        # Fused pass: a few slots per CPU thread (balance), one GPU thread per slot on CUDA (at most one per tile).
        slots = min(geo.tiles, CUDA_FUSED_SLOTS) if self.cuda else CPU_FUSED_SLOTS_PER_THREAD * taichi_setup.threads()
        buffers.allocate_fused(slots)
        # The fused kernel's layers argument when there are no layers (not written: with_layers is 0).
        self.no_layers = torch.zeros(NET_LAYERS * NET_SIDE * NET_SIDE, device=buffers.torch_device)

    def _v(self, array) -> torch.Tensor:
        view = self.t.get(id(array))
        if view is None:
            view = self.t[id(array)] = self.b.torch(array)
            # The kernels read rows of 8 or 16 floats as vectors, and Taichi's vector loads assume rows aligned
            # on their size (an unaligned one faults). Warp and torch allocate on 64 bytes and the band views
            # start on whole tiles; checked once per array.
            row_bytes = view.shape[-1] * view.element_size() if view.dim() and view.shape[-1] in (8, 16) else 1
            if view.data_ptr() % row_bytes:
                raise RuntimeError(f"Taichi backend: a buffer {tuple(view.shape)} at {view.data_ptr():#x} is not "
                                   f"aligned on its rows of {row_bytes} bytes")
        return view

    def _flat(self, array) -> torch.Tensor:
        """``array`` as one flat run (the correlations and layers: rows of 15 and 9 lags, stored one value at a
        time), made once."""
        key = ("flat", id(array))
        view = self.t.get(key)
        if view is None:
            view = self.t[key] = self._v(array).view(-1)
        return view

    def _runs(self, array) -> torch.Tensor:
        """``array`` (..., 16) as runs of ``taichi_texture.LANES`` pixels (..., 16 / LANES, LANES), made once."""
        key = ("runs", id(array))
        view = self.t.get(key)
        if view is None:
            tensor = self._v(array)
            lanes = taichi_texture.LANES
            view = self.t[key] = tensor.view(*tensor.shape[:-1], tensor.shape[-1] // lanes, lanes)
        return view

    def _argpacks(self) -> dict:
        """The kernels' argument packs, made once per Taichi runtime (``taichi_setup.argpacks``): they refer to the
        buffers' torch views, whose contents each call rewrites."""
        b, geo, cfg, v = self.b, self.geo, self.config, self._v
        return {
            "convert": taichi_convert.ConvertInputs(
                padded=v(b.padded), image_height=geo.height, image_width=geo.width, colours=geo.colours,
                masks=v(b.masks), kernels=v(b.kernels), kernel_rows=b.kernel_grid[0], kernel_cols=b.kernel_grid[1],
                use_kernels=int(b.use_kernels)),
            "correlate": taichi_correlate.CorrelateInputs(
                pairs=v(b.pairs), colours=geo.colours, used=v(b.used_colours), weights=v(b.used_weights),
                fat_zero=cfg.fat_zero, lpf_rb=v(b.lpf_rb), lpf_corr=v(b.lpf_corr), net_offset=cfg.net_offset),
            "fused": taichi_fused.FusedWork(
                tasks=v(b.tasks), count=v(b.count), positions=v(b.used_positions), scratch=v(b.scratch),
                written=v(b.written), layers_written=v(b.layers_written)),
            **({} if b.result.texture is None else {"texture": self._texture_inputs()}),  # textures=True
        }

    def _texture_inputs(self):
        b, geo, tc, v = self.b, self.geo, self.texture_config, self._v
        return taichi_texture.TextureInputs(
            tiles_x=geo.tiles_x, tiles_y=geo.tiles_y, ring_rows=b.ring_rows, lpf=v(b.tex_lpf), inv_cos=v(b.inv_cos),
            inv_sin=v(b.inv_sin), inv_window2=v(b.inv_window2), scale_shot=tc.scale_shot, min_shot=tc.min_shot,
            offsets=v(b.offsets), colour_weights=v(b.tex_weights_c), channel_of_colour=v(b.channel_of_colour),
            diff_sigma=tc.diff_sigma, weight_floor=tables.TEXTURE_WEIGHT_FLOOR, dust_remove=int(tc.dust_remove),
            output_gain=tc.output_gain, window2=self._runs(b.window2))

    def run(self, steps: tuple[str, ...], *, frames: torch.Tensor | None, masked: bool) -> None:
        with _TAICHI_LOCK:
            taichi_setup.use_arch(self.arch)
            self.packs = taichi_setup.argpacks(self, self._argpacks)
            try:
                self._run(steps, frames, masked)
            finally:
                self.packs = None  # kept by taichi_setup for the runtime that made them, not beyond it

    def _run(self, steps: tuple[str, ...], frames: torch.Tensor | None, masked: bool) -> None:
        if self.cuda:
            torch.cuda.current_stream(self.b.torch_device).synchronize()
        for step in steps:
            if step == "pad":
                taichi_frames.pad_frames(self.frames_t if frames is None else frames, self._v(self.b.padded))
            elif step == "fused":  # with the layers when they are asked for (made inside the fused kernel)
                self._fused(masked, "layers" in steps)
            elif step in ("convert", "convert_texture"):
                getattr(self, "_" + step)(masked)
            elif step == "layers":
                if "fused" not in steps:
                    self._layers()
            else:
                getattr(self, "_" + step)()
        if self.cuda:
            taichi_setup.ti.sync()

    def _centres(self) -> None:
        b = self.b
        taichi_frames.ideal_tile_centres(self._v(b.disparity), self._v(b.offsets), self._v(b.centres))

    def _convert(self, masked: bool) -> None:
        b = self.b
        self._convert_tiles(b.centres, b.active if masked else b.all_active, b.clt, b.finite, b.valid)

    def _convert_tiles(self, centres, active, clt, finite, valid) -> None:
        """convert_tiles over the tiles of ``centres`` (the frame's, or one band's views)."""
        v = self._v
        taichi_convert.convert_tiles(self.packs["convert"], v(centres), v(active), v(clt), v(finite), v(valid))

    def _fused(self, masked: bool, layers: bool) -> None:
        b, v, packs = self.b, self._v, self.packs
        layers = layers and b.layers is not None
        taichi_fused.fused_tiles(
            packs["convert"], packs["correlate"], packs["fused"], v(b.centres), v(b.active if masked else b.all_active),
            int(layers), self._flat(b.corr), self._flat(b.layers) if layers else self.no_layers, v(b.finite),
            v(b.valid),
        )

    def _correlate(self) -> None:
        b, v = self.b, self._v
        taichi_correlate.correlate_tiles(v(b.clt), v(b.finite), self.geo.cams, self.packs["correlate"],
                                         self._flat(b.corr))
        v(b.written).fill_(1)  # every tile's correlations were written, zero where not finite

    def _layers(self) -> None:
        """The network layers of every tile from its correlations (quad pairs; else none to make)."""
        b, v = self.b, self._v
        if b.layers is not None:
            taichi_correlate.network_layers(self._flat(b.corr), self.config.net_offset, self._flat(b.layers))
            v(b.layers_written).fill_(1)

    def _convert_texture(self, masked: bool) -> None:
        self._texture(convert=True, masked=masked)

    def _texture(self, convert: bool = False, masked: bool = False) -> None:
        """The texture band by band in ``backend.run_bands``' order; with ``convert``, each band converted first."""
        b, geo, v, tex = self.b, self.geo, self._v, self.packs["texture"]

        def convert_band(band) -> None:
            self._convert_tiles(band.centres, band.active if masked else band.all_active, band.clt, band.finite,
                                band.valid)

        def read_tiles(band) -> None:
            taichi_texture.texture_imclt(v(band.clt), v(band.finite), geo.cams, geo.colours, tex, v(band.pix),
                                         v(band.cmp))

        def write_pixels(band) -> None:
            runs = self._runs
            taichi_texture.texture_combine(runs(band.pix), runs(band.cmp), v(b.finite), band.first * geo.tiles_x,
                                           geo.cams, geo.colours, tex, runs(b.tex_rgba))
            taichi_texture.overlap_add(v(b.tex_rgba), v(b.finite), tex, band.y0, band.rows, v(b.canvas))

        run_bands(b.texture_bands, read_tiles, write_pixels, convert_band if convert else None)
