"""The tile processor's host class: owns every device buffer and launches the Warp or the Taichi kernels.

Built once for (image size, cameras, pairs, colours, kernels, device, backend); ``process`` only copies or maps
the inputs and launches. Results are torch tensors that share memory with the Warp buffers (``wp.to_torch``) on
the processor's device: they are overwritten by the next call (clone them to keep a frame's results). The Taichi
backend launches its kernels on the same buffers, through torch views (``ti.types.ndarray``, zero-copy), so
results, layouts and tables are the same for both backends.
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.config import CorrelationConfig, TextureConfig
from tpnet_gpu.kernels import convert, correlate, frames, texture
from tpnet_gpu.warp_setup import default_device, init_warp

# Warp's CPU tile kernels share one scratch arena: two concurrent launches abort the process (platform.md §1).
_CPU_LAUNCH_LOCK = threading.Lock()
# Taichi has one runtime per process (arch, threads, compiled kernels): its launches are serialised too.
_TAICHI_LOCK = threading.Lock()
CUDA_BLOCK_DIM = 64
BACKENDS = ("warp", "taichi")


@dataclass(frozen=True)
class TileResult:
    """Outputs of one ``TileProcessor.process`` call (views of the processor's buffers).

    Attributes:
        clt: ``(tiles, cams, colours, 4, 8, 8)`` frequency-domain tiles (CC, SC, CS, SS; colours R, B, G).
            Stale for inactive tiles, zero-filled windows where pixels were not finite.
        corr: ``(tiles, pairs, 15, 15)`` pair correlations, row = vertical lag + 7; zero where not computed.
        layers: ``(tiles, 4, 9, 9)`` network layers [hor, vert, diag-main, diag-other], or None unless the
            pairs are the quad's 6.
        valid: ``(tiles,)`` bool: active, every centre and window pixel finite, and every window wholly inside
            the image. Tiles with windows partly off the image still get values computed from pair-clamped
            pixels; tiles with non-finite input or inactive tiles get zero correlations.
        centres: ``(tiles, cams, 2)`` the per-camera tile centres (x, y) used, pixels.
        texture: ``(4, H, W)`` R, G, B, alpha (mono: ``(2, H, W)`` Y, alpha) overlap-added textures of the
            tiles with finite input, or None unless the processor was built with ``textures=True``. Colours are
            x ``output_gain`` (raw units); alpha ~1 where the cameras agree, ~0 where they do not or where no
            tile contributed (an empty texture is all zero).
    """

    clt: torch.Tensor
    corr: torch.Tensor
    layers: torch.Tensor | None
    valid: torch.Tensor
    centres: torch.Tensor
    texture: torch.Tensor | None


def _as_tuple_pairs(pairs, cams: int) -> tuple[tuple[int, int], ...]:
    out = tuple((int(a), int(b)) for a, b in pairs)
    if not out:
        raise ValueError("pairs: expected at least one (first, second) camera pair, got none")
    for a, b in out:
        if not (0 <= a < cams and 0 <= b < cams) or a == b:
            raise ValueError(f"pairs: expected distinct camera indices in 0..{cams - 1}, got {(a, b)}")
    return out


class TileProcessor:
    """Tile processor for frames of ``height`` x ``width`` pixels (multiples of 8, at least 16).

    Args:
        height, width: frame size in pixels.
        camera_offsets: ``(cams, 2)`` offsets r_i of the cameras from the virtual centre camera in baselines
            (x right, y down); camera i sees a tile at c - d r_i. Default: the ideal quad.
        pairs: camera pairs (first, second) to correlate; default the quad's 6 in the spec's order.
        cfa: 2x2 Bayer pattern of the raw frames ("GRBG", "RGGB", "BGGR", "GBRG"), or None for mono.
        kernels: optional aberration kernels in CLT form, ``(cams, colours, 4, 8, 8)`` (one per camera and
            colour) or ``(cams, rows, cols, colours, 4, 8, 8)`` on the 16-px kernel grid (node n at 16 n - 8).
        config: correlation parameters.
        textures: also make the RGBA texture image in ``process`` (allocates its buffers).
        texture_config: texture parameters.
        graph: record ``process``'s launches once as a Warp graph (a CUDA graph on the GPU) and replay it
            for every later frame; inputs are then always staged into the processor's buffers. Default: on
            CUDA with the Warp backend only (plain launches on the CPU). Warp only.
        device: Warp device ("cpu", "cuda", "cuda:0"); default cuda when present.
        backend: kernel language, "warp" or "taichi" (``kernels/taichi_*.py``: the same math, inputs and
            outputs; on the CPU it spreads the tiles over every core, see ``tpnet_gpu.taichi_setup`` for the
            thread count and the offline cache). Default (None): the faster by measurement (bench_throughput,
            README): Taichi on the CPU (3.1x Warp's speed for a full frame on 2 cores), Warp on CUDA and
            wherever ``graph`` is asked for.
    """

    def __init__(
        self,
        height: int,
        width: int,
        *,
        camera_offsets=tables.QUAD_OFFSETS,
        pairs=tables.QUAD_PAIRS,
        cfa: str | None = tables.DEFAULT_CFA,
        kernels=None,
        config: CorrelationConfig = CorrelationConfig(),
        textures: bool = False,
        texture_config: TextureConfig = TextureConfig(),
        graph: bool | None = None,
        device: str | None = None,
        backend: str | None = None,
    ):
        for name, value in (("height", height), ("width", width)):
            if not isinstance(value, (int, np.integer)) or value < 16 or value % 8:
                raise ValueError(f"{name}: expected a multiple of 8 that is at least 16, got {value!r}")
        offsets = np.asarray(camera_offsets, dtype=np.float32)
        if offsets.ndim != 2 or offsets.shape[1] != 2 or offsets.shape[0] < 2:
            raise ValueError(f"camera_offsets: expected shape (cams >= 2, 2), got {offsets.shape}")
        if backend is not None and backend not in BACKENDS:
            raise ValueError(f"backend: expected one of {BACKENDS} or None, got {backend!r}")
        if backend == "taichi" and graph:
            raise ValueError("graph: graph capture records Warp launches; it needs backend='warp', got backend='taichi'")
        init_warp()
        self.device = wp.get_device(device or default_device())
        if backend is None:
            backend = "warp" if (graph or self.device.is_cuda) else "taichi"
        self.backend = backend
        if backend == "taichi" and self.device.is_cuda and self.device.ordinal != 0:
            raise ValueError(f"device: the Taichi backend runs on cpu or cuda:0 only, got {self.device}")
        self.torch_device = torch.device(wp.device_to_torch(self.device))
        self.height, self.width = int(height), int(width)
        self.tiles_y, self.tiles_x = self.height // 8, self.width // 8
        self.tiles = self.tiles_y * self.tiles_x
        self.cams = offsets.shape[0]
        self.pairs = _as_tuple_pairs(pairs, self.cams)
        self.cfa = cfa
        self.colours = 1 if cfa is None else 3
        if cfa is not None:
            tables.cfa_red_position(cfa)  # validates the name
        self.config = config.resolved(self.colours)
        self.textures = bool(textures)
        self.texture_config = texture_config.resolved(self.colours)
        self.block_dim = 1 if self.device.is_cpu else CUDA_BLOCK_DIM
        self.graph = (self.device.is_cuda and backend == "warp") if graph is None else bool(graph)
        self._graphs: dict = {}  # (centres given, textures) -> recorded launches
        self._allocate(offsets)
        self._load_kernels(kernels)
        self._taichi = None
        if backend == "taichi":
            from tpnet_gpu.taichi_launch import TaichiLaunches  # noqa: PLC0415 - Taichi is imported only for this backend

            self._taichi = TaichiLaunches(self)

    # --- set-up ------------------------------------------------------------------------------------------
    def _array(self, data, dtype=wp.float32) -> wp.array:
        return wp.array(np.ascontiguousarray(data), dtype=dtype, device=self.device)

    def _allocate(self, offsets: np.ndarray) -> None:
        d, cams, tiles, colours, npairs = self.device, self.cams, self.tiles, self.colours, len(self.pairs)
        pad = 2 * frames.PAD
        self._frames = wp.zeros((cams, self.height, self.width), dtype=wp.float32, device=d)  # input staging
        self._padded = wp.zeros((cams, self.height + pad, self.width + pad), dtype=wp.float32, device=d)
        self._disparity = wp.zeros((self.tiles_y, self.tiles_x), dtype=wp.float32, device=d)
        self._active = wp.ones(tiles, dtype=wp.bool, device=d)
        self._all_active = wp.ones(tiles, dtype=wp.bool, device=d)
        self._centres = wp.zeros((tiles, cams, 2), dtype=wp.float32, device=d)
        self._clt = wp.zeros((tiles * cams * colours * 4, 8, 8), dtype=wp.float32, device=d)
        self._finite = wp.zeros(tiles, dtype=wp.bool, device=d)
        self._valid = wp.zeros(tiles, dtype=wp.bool, device=d)
        self._corr = wp.zeros((tiles * npairs, correlate.CORR_SIDE, correlate.CORR_SIDE), dtype=wp.float32, device=d)
        self._layers = None
        if self.pairs == tables.QUAD_PAIRS:
            self._layers = wp.zeros((tiles, 4, correlate.NET_SIDE, correlate.NET_SIDE), dtype=wp.float32, device=d)
        # Constant tables, all from tpnet_gpu.tables.
        self._offsets = wp.array(offsets, dtype=wp.vec2f, device=d)
        self._pairs = self._array(np.array(self.pairs, dtype=np.int32), dtype=wp.int32)
        self._masks = self._array(self._colour_masks())
        k = np.arange(8, dtype=np.float32)
        n = np.arange(16, dtype=np.float32)
        self._k_rows = self._array(np.broadcast_to(k[:, None], (8, 16)))
        self._n_rows = self._array(np.broadcast_to(n[None, :], (8, 16)))
        self._n_cols = self._array(np.broadcast_to(n[:, None], (16, 8)))
        self._k_cols = self._array(np.broadcast_to(k[None, :], (16, 8)))
        cfg = self.config
        self._colour_weights = self._array(np.array(cfg.colour_weights, dtype=np.float32))
        self._lpf_rb = self._array(tables.lpf(cfg.sigma_rb))
        self._lpf_corr = self._array(tables.lpf(cfg.sigma_corr))
        lags = [0.5 * tables.unfold_matrix(s, tables.CORR_RADIUS) @ tables.dtt2e_matrix(s) for s in (False, True)]
        self._lags_cos, self._lags_sin = (self._array(m) for m in lags)
        self._freqs_cos, self._freqs_sin = (self._array(m.T) for m in lags)
        texture_view = self._allocate_texture() if self.textures else None
        # Torch views of the outputs (zero-copy; made once).
        self._result = TileResult(
            clt=wp.to_torch(self._clt).view(tiles, cams, colours, 4, 8, 8),
            corr=wp.to_torch(self._corr).view(tiles, npairs, correlate.CORR_SIDE, correlate.CORR_SIDE),
            layers=None if self._layers is None else wp.to_torch(self._layers),
            valid=wp.to_torch(self._valid),
            centres=wp.to_torch(self._centres),
            texture=texture_view,
        )
        self._frames_t = wp.to_torch(self._frames)
        self._disparity_t = wp.to_torch(self._disparity)
        self._centres_t = self._result.centres
        self._active_t = wp.to_torch(self._active)
        self._active_in = self._all_active

    def _allocate_texture(self) -> torch.Tensor:
        """Texture buffers and tables; returns the image view ``(channels, H, W)`` of the canvas."""
        d, cams, colours = self.device, self.cams, self.colours
        n = self.tiles * cams * colours
        self._tex_pix = wp.zeros((n, 16, 16), dtype=wp.float32, device=d)
        self._tex_cmp = wp.zeros((n, 16, 16), dtype=wp.float32, device=d)
        self._tex_weights = wp.zeros((self.tiles * cams, 16, 16), dtype=wp.float32, device=d)
        self._canvas = wp.zeros((colours + 1, self.height + 8, self.width + 8), dtype=wp.float32, device=d)
        tc = self.texture_config
        self._tex_lpf = self._array(np.stack([tables.lpf(s) for s in tc.lpf_sigmas]))
        win = 0.5 * tables.half_sine(np.arange(16))
        inverse = [win[:, None] * (tables.fold_matrix(s).T @ tables.dtt4_matrix(s)) for s in (False, True)]
        self._inv_cos, self._inv_sin = (self._array(g) for g in inverse)
        self._inv_cos_t, self._inv_sin_t = (self._array(g.T) for g in inverse)
        self._tex_weights_c = self._array(np.array(tc.colour_weights, dtype=np.float32))
        # Output channels in R, G, B order (internal colour order is R, B, G).
        self._channel_of_colour = self._array(np.array([0, 2, 1] if colours == 3 else [0], dtype=np.int32), wp.int32)
        self._canvas_t = wp.to_torch(self._canvas)
        return self._canvas_t[:, 4 : 4 + self.height, 4 : 4 + self.width]

    def _colour_masks(self) -> np.ndarray:
        """(4 * colours, 16, 16) colour masks per window-corner parity [py, px, colour]; G carries its 0.5."""
        if self.cfa is None:
            return np.ones((4, 16, 16), dtype=np.float32)
        scale = np.array([1.0, 1.0, tables.GREEN_PRESCALE])
        masks = np.zeros((2, 2, 3, 16, 16), dtype=np.float32)
        colour = tables.cfa_colour_index(self.cfa, 18, 18)
        for py in range(2):
            for px in range(2):
                window = colour[py : py + 16, px : px + 16]
                for c in range(3):
                    masks[py, px, c] = np.where(window == c, scale[c], 0.0)
        return masks.reshape(12, 16, 16)

    def _load_kernels(self, kernels) -> None:
        if kernels is None:
            self._kernels = wp.zeros((4, 8, 8), dtype=wp.float32, device=self.device)  # unused placeholder
            self._kernel_grid = (1, 1)
            self._use_kernels = False
            return
        k = kernels.detach().cpu().numpy() if isinstance(kernels, torch.Tensor) else np.asarray(kernels)
        expected = f"(cams={self.cams}, [rows, cols,] colours={self.colours}, 4, 8, 8)"
        if k.ndim == 5:
            k = k[:, None, None]
        if k.ndim != 7 or k.shape[0] != self.cams or k.shape[3:] != (self.colours, 4, 8, 8):
            raise ValueError(f"kernels: expected shape {expected}, got {tuple(k.shape)}")
        if not np.all(np.isfinite(k)):
            raise ValueError("kernels: expected finite values, got NaN or infinity")
        self._kernel_grid = (k.shape[1], k.shape[2])
        self._use_kernels = True
        self._kernels = self._array(k.reshape(-1, 8, 8).astype(np.float32))

    # --- inputs --------------------------------------------------------------------------------------------
    def _frames_array(self, frames_in, *, stage: bool = False) -> wp.array:
        shape = (self.cams, self.height, self.width)
        if isinstance(frames_in, np.ndarray):
            frames_in = torch.from_numpy(frames_in)
        if not isinstance(frames_in, torch.Tensor):
            raise TypeError(f"frames: expected a torch tensor or numpy array, got {type(frames_in).__name__}")
        if tuple(frames_in.shape) != shape:
            raise ValueError(f"frames: expected shape {shape} (cams, height, width), got {tuple(frames_in.shape)}")
        if frames_in.dtype.is_complex or frames_in.dtype == torch.bool:
            raise TypeError(f"frames: expected real pixel values (float or integer), got {frames_in.dtype}")
        if (
            not stage
            and frames_in.dtype == torch.float32
            and frames_in.device == self.torch_device
            and frames_in.is_contiguous()
        ):
            return wp.from_torch(frames_in, requires_grad=False)  # zero-copy
        self._frames_t.copy_(frames_in)  # into the preallocated staging buffer (converts dtype and device)
        return self._frames

    def _set_disparity(self, target_disparity) -> None:
        shape = (self.tiles_y, self.tiles_x)
        if isinstance(target_disparity, (int, float, np.floating, np.integer)):
            self._disparity_t.fill_(float(target_disparity))
            return
        if isinstance(target_disparity, np.ndarray):
            target_disparity = torch.from_numpy(target_disparity)
        if not isinstance(target_disparity, torch.Tensor):
            raise TypeError(
                f"target_disparity: expected a number, torch tensor or numpy array, got {type(target_disparity).__name__}"
            )
        if tuple(target_disparity.shape) != shape:
            raise ValueError(
                f"target_disparity: expected shape {shape} (tiles_y, tiles_x), got {tuple(target_disparity.shape)}"
            )
        if not target_disparity.dtype.is_floating_point:
            raise TypeError(f"target_disparity: expected a floating-point dtype, got {target_disparity.dtype}")
        self._disparity_t.copy_(target_disparity)

    def _set_centres(self, centres) -> None:
        shape = (self.tiles, self.cams, 2)
        if isinstance(centres, np.ndarray):
            centres = torch.from_numpy(centres)
        if not isinstance(centres, torch.Tensor) or tuple(centres.shape) != shape:
            got = tuple(centres.shape) if hasattr(centres, "shape") else type(centres).__name__
            raise ValueError(f"centres: expected shape {shape} (tiles, cams, x/y), got {got}")
        if not centres.dtype.is_floating_point:
            raise TypeError(f"centres: expected a floating-point dtype, got {centres.dtype}")
        self._centres_t.copy_(centres)

    def _active_array(self, active) -> wp.array:
        if active is None:
            return self._all_active
        if isinstance(active, np.ndarray):
            active = torch.from_numpy(active)
        if not isinstance(active, torch.Tensor) or active.dtype != torch.bool or active.numel() != self.tiles:
            got = f"{active.dtype} of shape {tuple(active.shape)}" if isinstance(active, torch.Tensor) else type(active)
            raise ValueError(f"active: expected a bool mask of {self.tiles} tiles (tiles_y, tiles_x), got {got}")
        self._active_t.copy_(active.reshape(-1))
        return self._active

    # --- per frame -------------------------------------------------------------------------------------------
    def process(self, frames_in, target_disparity=None, *, centres=None, active=None) -> TileResult:
        """Convert and correlate one set of camera frames.

        Args:
            frames_in: ``(cams, height, width)`` raw frames (Bayer mosaics in ``cfa``, or mono), torch tensor
                on any device or numpy array, any real dtype. A float32 contiguous tensor on the processor's
                device is read in place; anything else is copied into the processor's staging buffer.
            target_disparity: a number or ``(tiles_y, tiles_x)`` target disparities (px) of the ideal rig;
                NaN masks the tile. Give this or ``centres``.
            centres: ``(tiles, cams, 2)`` per-camera tile centres (x, y) in pixels, e.g. from a calibrated
                camera model; NaN masks the tile.
            active: optional ``(tiles_y, tiles_x)`` bool mask of tiles to process.

        Returns:
            TileResult of torch tensors on the processor's device (views, overwritten by the next call).
        """
        if not self.graph:
            self.prepare(frames_in, target_disparity, centres=centres, active=active)
            self.convert()
            self.correlate()
            if self.textures:
                self.texture()
            return self._result
        frames_wp = self._stage_inputs(frames_in, target_disparity, centres, active, stage=True)
        key = (centres is not None, self.textures)
        with self._launching() as stream:
            if key not in self._graphs:  # record once; every launch reads the processor's own buffers
                with wp.ScopedCapture(device=self.device, stream=stream) as capture:
                    self._launch_all(frames_wp, centres is None)
                self._graphs[key] = capture.graph
            wp.capture_launch(self._graphs[key], stream=stream)
        return self._result

    def _launch_all(self, frames_wp: wp.array, ideal: bool) -> None:
        self._launch_prepare(frames_wp, ideal)
        self._launch_convert()
        self._launch_correlate()
        if self.textures:
            self._launch_texture()

    @contextlib.contextmanager
    def _launching(self, backend: str | None = None):
        """Warp: serialise CPU tile launches (platform.md §1) and, on CUDA, run Warp on torch's current stream so
        torch's input copies and readers of the outputs are ordered with the kernels. Yields the stream.
        Taichi (``backend`` defaults to the processor's): serialise launches (one runtime per process), make the
        processor's arch current and, on CUDA, wait for torch's stream before and for Taichi after the kernels."""
        if (backend or self.backend) == "taichi":
            from tpnet_gpu import taichi_setup  # noqa: PLC0415

            with _TAICHI_LOCK:
                taichi_setup.use_arch(self._taichi.arch)
                if self.device.is_cuda:
                    torch.cuda.current_stream(self.torch_device).synchronize()
                yield None
                if self.device.is_cuda:
                    taichi_setup.ti.sync()
            return
        with _CPU_LAUNCH_LOCK:
            if self.device.is_cuda:
                stream = wp.stream_from_torch(torch.cuda.current_stream(self.torch_device))
                with wp.ScopedStream(stream):
                    yield stream
            else:
                yield None

    @property
    def result(self) -> TileResult:
        """The output views (what ``process`` returns), as the stages last left them."""
        return self._result

    # --- stages (public so benchmarks can time them; ``process`` runs them in order) ----------------------------
    def prepare(self, frames_in, target_disparity=None, *, centres=None, active=None) -> None:
        """Stage 0: map or copy the inputs, pad the frames (pair clamp) and compute the tile centres."""
        frames_wp = self._stage_inputs(frames_in, target_disparity, centres, active)
        with self._launching():
            self._launch_prepare(frames_wp, centres is None)

    def _stage_inputs(self, frames_in, target_disparity, centres, active, *, stage: bool = False) -> wp.array:
        """Check the inputs and copy (or map) them into the processor's buffers; returns the frames' array."""
        if (target_disparity is None) == (centres is None):
            raise ValueError("process: give exactly one of target_disparity and centres")
        frames_wp = self._frames_array(frames_in, stage=stage)
        self._active_in = self._active_array(active)
        if stage and active is None:  # a recorded graph reads one fixed mask buffer
            self._active_t.fill_(True)
            self._active_in = self._active
        if centres is None:
            self._set_disparity(target_disparity)
        else:
            self._set_centres(centres)
        return frames_wp

    def _launch_prepare(self, frames_wp: wp.array, ideal: bool) -> None:
        if self._taichi is not None:
            frames_t = self._frames_t if frames_wp is self._frames else wp.to_torch(frames_wp, requires_grad=False)
            self._taichi.prepare(frames_t, ideal)
            return
        d = self.device
        if ideal:
            wp.launch(
                frames.ideal_tile_centres,
                dim=(self.tiles_y, self.tiles_x, self.cams),
                inputs=[self._disparity, self._offsets],
                outputs=[self._centres],
                device=d,
            )
        wp.launch(frames.pad_frames, dim=self._padded.shape, inputs=[frames_wp], outputs=[self._padded], device=d)

    def convert(self) -> None:
        """Stage 1: padded frames and centres -> CLT tiles, finite and valid masks."""
        with self._launching():
            self._launch_convert()

    def correlate(self) -> None:
        """Stage 2: CLT tiles -> pair correlations (and the network layers for the quad's pairs)."""
        with self._launching():
            self._launch_correlate()

    def texture(self) -> None:
        """Stage 3: CLT tiles -> RGBA texture image (needs ``textures=True`` at construction)."""
        if not self.textures:
            raise RuntimeError("texture: this processor was built without textures=True")
        with self._launching():
            self._launch_texture()

    def _launch_convert(self) -> None:
        if self._taichi is not None:
            self._taichi.convert(every_tile=self._active_in is not self._active)
            return
        wp.launch_tiled(
            convert.convert_tiles,
            dim=[self.tiles],
            inputs=[
                self._padded, self._centres, self._active_in, self._masks, self._k_rows, self._n_rows,
                self._n_cols, self._k_cols, self._kernels, self._kernel_grid[0], self._kernel_grid[1],
                self._use_kernels, self.height, self.width, self.colours,
            ],
            outputs=[self._clt, self._finite, self._valid],
            block_dim=self.block_dim,
            device=self.device,
        )

    def _launch_correlate(self) -> None:
        cfg = self.config
        if self._taichi is not None:
            self._taichi.correlate()
            return
        wp.launch_tiled(
            correlate.correlate_tiles,
            dim=[self.tiles],
            inputs=[
                self._clt, self._finite, self._pairs, self.cams, self.colours, self._colour_weights,
                cfg.fat_zero, self._lpf_rb, self._lpf_corr, self._lags_cos, self._lags_sin, self._freqs_cos,
                self._freqs_sin,
            ],
            outputs=[self._corr],
            block_dim=self.block_dim,
            device=self.device,
        )
        if self._layers is not None:
            wp.launch(
                correlate.network_layers,
                dim=self._layers.shape,
                inputs=[self._corr, cfg.net_offset],
                outputs=[self._layers],
                device=self.device,
            )

    def _launch_texture(self) -> None:
        tc, d = self.texture_config, self.device
        if self._taichi is not None:
            self._taichi.texture()
            return
        per_pixel = (self.tiles * self.cams * self.colours, 16, 16)
        wp.launch(texture.clear_canvas, dim=self._canvas.shape, outputs=[self._canvas], device=d)
        wp.launch_tiled(
            texture.texture_imclt,
            dim=[self.tiles],
            inputs=[self._clt, self._finite, self.cams, self.colours, self._tex_lpf, self._inv_cos,
                    self._inv_sin, self._inv_cos_t, self._inv_sin_t],
            outputs=[self._tex_pix],
            block_dim=self.block_dim,
            device=d,
        )
        wp.launch(
            texture.texture_demosaic,
            dim=per_pixel,
            inputs=[self._tex_pix, self._finite, self.cams, self.colours, tc.scale_shot, tc.min_shot],
            outputs=[self._tex_cmp],
            device=d,
        )
        wp.launch(
            texture.texture_combine,
            dim=(self.tiles, 16, 16),
            inputs=[self._tex_pix, self._tex_cmp, self._finite, self.tiles_x, self.tiles_y, self.cams,
                    self.colours, self._offsets, self._tex_weights_c, self._channel_of_colour, tc.diff_sigma,
                    tables.TEXTURE_WEIGHT_FLOOR, tc.dust_remove, tc.output_gain],
            outputs=[self._tex_weights, self._canvas],
            device=d,
        )
