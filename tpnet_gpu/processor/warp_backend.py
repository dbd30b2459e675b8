"""The Warp backend: launches of kernels/frames.py, convert.py, correlate.py, texture.py over ``Buffers``.

Streams and graphs (CUDA): launches go to torch's current stream, through one Warp stream wrapper per torch
stream, so torch's copies and readers are ordered with the kernels. A step sequence is recorded as a CUDA graph
once, on a private Warp stream - capture is illegal on the legacy default stream that torch normally uses - and
replayed with ``wp.capture_launch(graph, stream=<torch's stream>)``. Every launch on CUDA, tiled or per thread,
uses ``CUDA_BLOCK_DIM``: Warp compiles a module once per block size, so one size means one build per module.
On the CPU a block is one lane and a "graph" is Warp's recorded launches. The fused pass runs one block on the
CPU (a launch is serial there anyway) and ``CUDA_FUSED_SLOTS`` blocks (at most one per tile) on CUDA, each looping
over its share of the task list.
"""

from __future__ import annotations

import contextlib
import threading

import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.config import CorrelationConfig, TextureConfig
from tpnet_gpu.kernels import convert, correlate, frames, fused, texture
from tpnet_gpu.layout import CPU_BLOCK_DIM, CUDA_BLOCK_DIM, CUDA_FUSED_SLOTS
from tpnet_gpu.processor.backend import run_bands
from tpnet_gpu.processor.buffers import Buffers
from tpnet_gpu.processor.validate import Geometry

# Warp's CPU tile kernels share one scratch arena: two concurrent launches abort the process (platform.md §1).
_CPU_LAUNCH_LOCK = threading.Lock()
KERNEL_MODULES = (frames, convert, correlate, fused, texture)


def make_struct(struct, **fields):
    """An instance of the Warp struct type ``struct`` with every one of its fields set from ``fields``."""
    if set(fields) != set(struct.vars):
        raise TypeError(f"{struct.key}: expected the fields {sorted(struct.vars)}, got {sorted(fields)}")
    instance = struct()
    for name, value in fields.items():
        setattr(instance, name, value)
    return instance


class WarpBackend:
    """Warp launches of one processor's steps (see the module docstring)."""

    name = "warp"

    def __init__(self, geo: Geometry, config: CorrelationConfig, texture_config: TextureConfig | None,
                 buffers: Buffers, *, graph: bool):
        self.geo, self.config, self.texture_config, self.b = geo, config, texture_config, buffers
        self.device = buffers.device
        self.block_dim = CUDA_BLOCK_DIM if self.device.is_cuda else CPU_BLOCK_DIM
        self.graph = graph
        self.graphs: dict[tuple[str, ...], wp.Graph] = {}  # steps -> recorded launches
        self._streams: dict[int, wp.Stream] = {}  # torch stream handle -> its Warp wrapper
        self._capture_stream = wp.Stream(self.device) if graph and self.device.is_cuda else None
        self._lock = _CPU_LAUNCH_LOCK if self.device.is_cpu else threading.Lock()
        self.slots = min(geo.tiles, CUDA_FUSED_SLOTS) if self.device.is_cuda else 1
        buffers.allocate_fused(self.slots)
        # The kernels' argument structs, made once: they refer to the buffers, whose contents each call rewrites.
        b, cfg, tc = buffers, config, texture_config
        self.convert_in = make_struct(
            convert.ConvertInputs, padded=b.padded, image_height=geo.height, image_width=geo.width,
            colours=geo.colours, masks=b.masks, k_rows=b.k_rows, n_rows=b.n_rows, n_cols=b.n_cols, k_cols=b.k_cols,
            kernels=b.kernels, kernel_rows=b.kernel_grid[0], kernel_cols=b.kernel_grid[1], use_kernels=b.use_kernels)
        self.correlate_in = make_struct(
            correlate.CorrelateInputs, pairs=b.pairs, colours=geo.colours, used=b.used_colours, weights=b.used_weights,
            fat_zero=cfg.fat_zero, lpf_rb=b.lpf_rb, lpf_corr=b.lpf_corr, lags_cos=b.lags_cos, lags_sin=b.lags_sin,
            freqs_cos=b.freqs_cos, freqs_sin=b.freqs_sin)
        self.fused_work = make_struct(fused.FusedWork, tasks=b.tasks, count=b.count, slots=self.slots,
                                      positions=b.used_positions, scratch=b.scratch, written=b.written)
        self.texture_in = None if b.result.texture is None else make_struct(  # texture buffers: textures=True
            texture.TextureInputs, cams=geo.cams, colours=geo.colours, tiles_x=geo.tiles_x, tiles_y=geo.tiles_y,
            ring_rows=b.ring_rows, lpf=b.tex_lpf, inv_cos=b.inv_cos, inv_sin=b.inv_sin, inv_cos_t=b.inv_cos_t,
            inv_sin_t=b.inv_sin_t, inv_window2=b.inv_window2, scale_shot=tc.scale_shot, min_shot=tc.min_shot,
            offsets=b.offsets, colour_weights=b.tex_weights_c, channel_of_colour=b.channel_of_colour,
            diff_sigma=tc.diff_sigma, weight_floor=tables.TEXTURE_WEIGHT_FLOOR, dust_remove=tc.dust_remove,
            output_gain=tc.output_gain)

    # --- streams and graphs --------------------------------------------------------------------------------
    def _torch_stream(self) -> wp.Stream | None:
        """The Warp wrapper of torch's current stream (one per torch stream), None on the CPU."""
        if not self.device.is_cuda:
            return None
        current = torch.cuda.current_stream(self.b.torch_device)
        stream = self._streams.get(current.cuda_stream)
        if stream is None:
            stream = self._streams[current.cuda_stream] = wp.stream_from_torch(current)
        return stream

    def _record(self, steps: tuple[str, ...], frames_t, masked: bool) -> wp.Graph:
        for module in KERNEL_MODULES:  # compiled before capture, at the one block size launches use
            wp.load_module(module, device=self.device, block_dim=self.block_dim)
        stream = self._capture_stream
        scope = wp.ScopedStream(stream, sync_enter=False) if stream is not None else contextlib.nullcontext()
        with scope, wp.ScopedCapture(device=self.device, stream=stream, force_module_load=False) as capture:
            self._launch(steps, frames_t, masked)
        return capture.graph

    def run(self, steps: tuple[str, ...], *, frames: torch.Tensor | None, masked: bool) -> None:
        with self._lock:
            stream = self._torch_stream()
            if self.graph:
                if frames is not None:
                    raise RuntimeError("graph replay reads the processor's staging buffer; stage the frames first")
                if steps not in self.graphs:
                    self.graphs[steps] = self._record(steps, None, masked)
                wp.capture_launch(self.graphs[steps], stream=stream)
                return
            scope = wp.ScopedStream(stream, sync_enter=False) if stream is not None else contextlib.nullcontext()
            with scope:
                self._launch(steps, frames, masked)

    # --- launches --------------------------------------------------------------------------------------------
    def _launch(self, steps: tuple[str, ...], frames_t, masked: bool) -> None:
        for step in steps:
            if step == "pad":
                self._pad(frames_t)
            elif step in ("convert", "fused", "convert_texture"):
                getattr(self, "_" + step)(masked)
            else:
                getattr(self, "_" + step)()

    def _thread_launch(self, kernel, dim, inputs, outputs) -> None:
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.device, block_dim=self.block_dim)

    def _tile_launch(self, kernel, inputs, outputs) -> None:
        self._tile_launch_n(kernel, self.geo.tiles, inputs, outputs)

    def _tile_launch_n(self, kernel, tiles: int, inputs, outputs) -> None:
        wp.launch_tiled(kernel, dim=[tiles], inputs=inputs, outputs=outputs, block_dim=self.block_dim,
                        device=self.device)

    def _pad(self, frames_t: torch.Tensor | None) -> None:
        b = self.b
        source = b.frames if frames_t is None else wp.from_torch(frames_t, requires_grad=False)
        self._thread_launch(frames.pad_frames, b.padded.shape, [source], [b.padded])

    def _centres(self) -> None:
        b, geo = self.b, self.geo
        self._thread_launch(frames.ideal_tile_centres, (geo.tiles_y, geo.tiles_x, geo.cams), [b.disparity, b.offsets],
                            [b.centres])

    def _convert(self, masked: bool) -> None:
        b = self.b
        self._convert_tiles(b.centres, b.active if masked else b.all_active, b.clt, b.finite, b.valid)

    def _convert_tiles(self, centres, active, clt, finite, valid) -> None:
        """convert_tiles over the tiles of ``centres`` (the frame's, or one band's views)."""
        self._tile_launch_n(convert.convert_tiles, centres.shape[0],
                            [self.convert_in, centres, active, self.b.all_colours], [clt, finite, valid])

    def _correlate(self) -> None:
        b = self.b
        self._tile_launch(correlate.correlate_tiles, [b.clt, b.finite, self.geo.cams, self.correlate_in], [b.corr])
        b.written.fill_(True)  # every tile's correlations were written (zero where not finite)

    def _layers(self) -> None:
        """The network layers of every tile from its correlations (quad pairs; else none to make)."""
        b = self.b
        if b.layers is not None:
            self._thread_launch(correlate.network_layers, b.layers.shape, [b.corr, self.config.net_offset],
                                [b.layers])

    def _fused(self, masked: bool) -> None:
        b, geo = self.b, self.geo
        self._thread_launch(fused.reset_count, 1, [self.fused_work], [])
        self._thread_launch(fused.compact_tasks, geo.tiles,
                            [b.active if masked else b.all_active, len(geo.pairs), self.fused_work],
                            [b.finite, b.valid, b.corr])
        wp.launch_tiled(
            fused.fused_tiles, dim=[self.slots],
            inputs=[self.fused_work, self.convert_in, b.centres, self.correlate_in],
            outputs=[b.corr, b.finite, b.valid], block_dim=self.block_dim, device=self.device,
        )

    def _convert_texture(self, masked: bool) -> None:
        self._texture(convert=True, masked=masked)

    def _texture(self, convert: bool = False, masked: bool = False) -> None:
        """The texture one band of tile rows at a time through the scratch (Buffers), in ``backend.run_bands``'
        order; with ``convert``, each band's CLT tiles are converted into the band buffer first (a processor
        without the whole-frame one)."""
        b, geo, tex = self.b, self.geo, self.texture_in

        def convert_band(band) -> None:
            self._convert_tiles(band.centres, band.active if masked else band.all_active, band.clt, band.finite,
                                band.valid)

        def read_tiles(band) -> None:
            self._tile_launch_n(texture.texture_imclt, band.finite.shape[0], [band.clt, band.finite, tex], [band.pix])
            self._thread_launch(texture.texture_demosaic, band.pix.shape, [band.pix, band.finite, tex], [band.cmp])

        def write_pixels(band) -> None:
            self._thread_launch(texture.texture_combine, (band.finite.shape[0], *b.tex_pix.shape[1:]),
                                [band.pix, band.cmp, b.finite, band.first * geo.tiles_x, tex],
                                [band.weights, b.tex_rgba])
            self._thread_launch(texture.overlap_add, (b.canvas.shape[0], band.rows, b.canvas.shape[2]),
                                [b.tex_rgba, b.finite, tex, band.y0], [b.canvas])

        run_bands(b.texture_bands, read_tiles, write_pixels, convert_band if convert else None)
