"""``TileProcessor``: the public host object of the tile processor (tile_processor.md §1, §8).

Built once for (frame size, cameras, pairs, colours, kernels, device, backend): validates its arguments
(``validate``), allocates every buffer (``Buffers``) and picks a backend (Warp or Taichi). Per frame it only
maps or copies the inputs into those buffers and has the backend launch. A frame is loaded once (``load``:
staging and padding) and can then be measured at any number of targets (``measure``), as the pipeline's passes
do; ``process`` is load + measure (+ texture) in one call. Results are zero-copy torch views of the buffers on
the processor's device, overwritten by the next call (clone them to keep a frame's results).

Fused or split: ``measure`` runs the fused pass - one launch that converts and correlates each active tile (a
task list of them) without writing the frequency-domain (CLT) tiles - unless the processor was built with
``clt=True``: then it runs the split stages (convert, then correlate) and ``result.clt`` holds the tiles. The
whole-frame CLT buffer (~1 GB at 2592x1936 quad) exists only with ``clt=True``; a texturing processor without it
converts the tiles for the texture band by band (``TEXTURE_BAND_ROWS`` tile rows) into a band-sized buffer, so its
``measure`` and ``process`` correlate fused. With ``clt=True``, ``texture`` converts the tiles first when the last
targets have not been converted. Both paths give the same correlations, layers and masks (tests compare each
to the float64 reference); without the buffer ``result.clt`` is None. The network layers (quad pairs) are a
step of their own (``measure(layers=False)`` leaves them out: ``result.layers`` is then None).

Threads: a processor belongs to the thread that first gives it work (``load``, ``set_targets`` or a stage); a
call from any other thread while that one is alive raises ``RuntimeError`` - its results are views that another
thread's call would overwrite under it (issue 16: two threads got each other's results). A caller may keep the
views until its own next call on the processor; to keep them longer, or to hand them to another thread, clone
them. Build one processor per thread (launches of several processors are serialised by the backends).
"""

from __future__ import annotations

import threading
from dataclasses import replace

import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.config import SMALL_FRAME_PIXELS, CorrelationConfig, TextureConfig
from tpnet_gpu.processor import validate
from tpnet_gpu.processor.buffers import Buffers, TileResult
from tpnet_gpu.processor.warp_backend import WarpBackend
from tpnet_gpu.runtime.warp_setup import init_warp


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
        textures: also make the RGBA texture image in ``process`` and ``texture`` (allocates its buffers: one
            band of CLT tiles the texture converts into, unless ``clt``; ``measure`` stays fused).
        clt: keep the whole frame's CLT tiles (``result.clt``, the ``convert``/``correlate`` stages; ~1 GB at
            5 MPix); else ``measure`` runs the fused pass (module docstring).
        texture_config: texture parameters.
        graph: record each step sequence's launches once as a Warp graph (a CUDA graph on the GPU) and replay
            it for every later call; inputs are then always staged into the processor's buffers. Default: on
            CUDA with the Warp backend only (plain launches on the CPU). Warp only.
        device: "cpu", "cuda", "cuda:N" or such a ``torch.device``; default cuda when present (anything else, or
            CUDA where none is present, is a ``ValueError`` naming ``device``).
        backend: kernel language, "warp" or "taichi" (``kernels/taichi_*.py``: the same math, inputs and
            outputs; on the CPU it spreads the tiles over every core, see ``tpnet_gpu.runtime.taichi_setup`` for the
            thread count and the offline cache). Default (None): the faster by measurement (bench_throughput,
            README): Taichi on the CPU (3.1x Warp's speed for a full frame on 2 cores), Warp on CUDA, wherever
            ``graph`` is asked for, and for frames of at most ``config.SMALL_FRAME_PIXELS`` (start-up bound: Warp
            starts ~1 CPU-second sooner and runs them as fast).
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
        clt: bool = False,
        texture_config: TextureConfig = TextureConfig(),
        graph: bool | None = None,
        device: str | None = None,
        backend: str | None = None,
    ):
        geo = validate.geometry(height, width, camera_offsets, pairs, cfa)
        validate.backend(backend, graph)
        init_warp()
        self.device = wp.get_device(validate.device(device))
        if backend is None:  # Warp on CUDA and for small frames (config.SMALL_FRAME_PIXELS), else Taichi
            backend = "warp" if (graph or self.device.is_cuda or height * width <= SMALL_FRAME_PIXELS) else "taichi"
        if backend == "taichi" and self.device.is_cuda and self.device.ordinal != 0:
            raise ValueError(f"device: the Taichi backend runs on cpu or cuda:0 only, got {self.device}")
        self.geometry = geo
        self.config = config.resolved(geo.colours)
        self.textures = bool(textures)
        if self.textures:
            validate.distinct_offsets(geo.offsets)
        self.keeps_clt = bool(clt)  # measure keeps the CLT tiles (split stages)
        self._converted = False  # the CLT tiles are those of the current targets
        self.texture_config = texture_config.resolved(geo.colours)
        self.graph = (self.device.is_cuda and backend == "warp") if graph is None else bool(graph)
        self._buffers = Buffers(geo, self.config, self.texture_config if self.textures else None,
                                validate.kernels(kernels, geo), self.device, keep_clt=self.keeps_clt)
        if backend == "taichi":
            from tpnet_gpu.processor.taichi_backend import TaichiBackend  # noqa: PLC0415 - Taichi only when asked

            self._backend = TaichiBackend(geo, self.config, self.texture_config, self._buffers)
        else:
            self._backend = WarpBackend(geo, self.config, self.texture_config, self._buffers, graph=self.graph)
        self._masked = False  # the last targets came with an active mask
        self._layers_made = True  # the last correlations came with their layers (measure(layers=False): not)
        self._without_layers = replace(self._buffers.result, layers=None)
        self._ideal = True  # the last targets were disparities (centres computed on the device)
        self._frame_count = 0
        self._owner: threading.Thread | None = None  # the thread whose calls the result views belong to
        self._owner_lock = threading.Lock()  # two first calls at once: one of them becomes the owner
        if self.device.is_cuda:  # the zero-fills above must finish before a user's side stream writes inputs
            wp.synchronize_device(self.device)

    # --- what it was built for ---------------------------------------------------------------------------------
    backend = property(lambda self: self._backend.name, doc='"warp" or "taichi".')
    torch_device = property(lambda self: self._buffers.torch_device, doc="The torch device of the results.")
    height = property(lambda self: self.geometry.height)
    width = property(lambda self: self.geometry.width)
    tiles_y = property(lambda self: self.geometry.tiles_y)
    tiles_x = property(lambda self: self.geometry.tiles_x)
    tiles = property(lambda self: self.geometry.tiles)
    cams = property(lambda self: self.geometry.cams)
    colours = property(lambda self: self.geometry.colours)
    pairs = property(lambda self: self.geometry.pairs)
    cfa = property(lambda self: self.geometry.cfa)

    @property
    def frame_count(self) -> int:
        """How many frames ``load`` (or ``process``/``prepare``) has taken: a caller that loaded a frame and
        measures it later can tell whether someone loaded another one in between."""
        return self._frame_count

    @property
    def staging(self) -> torch.Tensor:
        """The ``(cams, height, width)`` float32 staging buffer ``load`` copies frames into: a caller may write a
        frame there (e.g. scaled) and ``load`` it, which then reads it in place (no copy without graphs)."""
        return self._buffers.frames_t

    @property
    def result(self) -> TileResult:
        """The output views (what ``process`` returns), as the stages last left them (``layers`` None after a
        ``measure(layers=False)``)."""
        return self._buffers.result if self._layers_made else self._without_layers

    # --- per frame ---------------------------------------------------------------------------------------------
    def load(self, frames) -> None:
        """Map or copy one set of camera frames and pad them (pair clamp); later ``measure`` calls read them.

        Args:
            frames: ``(cams, height, width)`` raw frames (Bayer mosaics in ``cfa``, or mono), torch tensor on any
                device or numpy array, any real dtype. A float32 contiguous tensor on the processor's device is
                read in place (without graphs); anything else is copied into the processor's staging buffer.
        """
        self._claim("load")
        frames = validate.frames(frames, self.geometry)
        b = self._buffers
        in_place = (not self.graph and frames.dtype == torch.float32 and frames.device == b.torch_device
                    and frames.is_contiguous())
        if not in_place:
            b.frames_t.copy_(frames)  # converts dtype and device
        self._backend.run(("pad",), frames=frames if in_place else None, masked=False)
        self._frame_count += 1
        self._converted = False

    def set_targets(self, target_disparity=None, *, centres=None, active=None) -> None:
        """Copy one pass's targets into the processor's buffers (see ``measure`` for the arguments)."""
        self._claim("set_targets")
        validate.targets(target_disparity, centres)
        geo, b = self.geometry, self._buffers
        mask = validate.active(active, geo)
        if centres is None:
            target = validate.target_disparity(target_disparity, geo)
            if isinstance(target, float):
                b.disparity_t.fill_(target)
            else:
                b.disparity_t.copy_(target)
        else:
            b.result.centres.copy_(validate.centres(centres, geo))
        if mask is not None:
            b.active_t.copy_(mask)
        elif self.graph:  # a recorded graph reads one fixed mask buffer
            b.active_t.fill_(True)
        self._masked = mask is not None or self.graph
        self._ideal = centres is None
        self._converted = False

    def measure(self, target_disparity=None, *, centres=None, active=None, layers: bool = True) -> TileResult:
        """Convert and correlate the loaded frames at new targets.

        Args:
            target_disparity: a number or ``(tiles_y, tiles_x)`` target disparities (px) of the ideal rig;
                NaN masks the tile. Give this or ``centres``.
            centres: ``(tiles, cams, 2)`` per-camera tile centres (x, y) in pixels, e.g. from a calibrated
                camera model; NaN masks the tile.
            active: optional ``(tiles_y, tiles_x)`` bool mask of tiles to process.
            layers: also make the network layers (a processor of the quad's pairs); False: this pass makes none
                and its result's ``layers`` is None (the disparity engine reads only the correlations: the layers
                are ~8 % of a fused pass on the CPU).

        Returns:
            TileResult of torch tensors on the processor's device (views, overwritten by the next call).
        """
        self.set_targets(target_disparity, centres=centres, active=active)
        self._run(self._pass(layers))  # split with clt=True, else fused (module docstring)
        return self.result

    def process(self, frames, target_disparity=None, *, centres=None, active=None) -> TileResult:
        """``load`` + ``measure`` of one set of frames, and the texture when built with ``textures=True``."""
        validate.targets(target_disparity, centres)
        self.load(frames)
        self.set_targets(target_disparity, centres=centres, active=active)
        self._run((*self._pass(), self._texture_step) if self.textures else self._pass())
        return self.result

    def _pass(self, layers: bool = True) -> tuple[str, ...]:
        """The steps of one measurement: split when the CLT tiles are kept, else fused; then the layers."""
        return (*(("convert", "correlate") if self.keeps_clt else ("fused",)), *(("layers",) if layers else ()))

    @property
    def _texture_step(self) -> str:
        """The texture from the converted whole-frame CLT tiles, or converted band by band into the band buffer."""
        return "texture" if self.keeps_clt else "convert_texture"

    def _claim(self, call: str) -> None:
        """Make the calling thread the owner, or refuse while another living thread owns the processor."""
        me = threading.current_thread()
        if self._owner is me:
            return
        with self._owner_lock:
            owner = self._owner
            if owner is not None and owner is not me and owner.is_alive():
                raise RuntimeError(
                    f"{call}: this TileProcessor belongs to thread {owner.name!r} (its results are views of the "
                    f"processor's buffers that a call from thread {me.name!r} would overwrite); build one "
                    "processor per thread")
            self._owner = me

    def _run(self, steps: tuple[str, ...]) -> None:
        self._claim("/".join(steps))
        if self._ideal and any(step in steps for step in ("convert", "fused", "convert_texture")):
            steps = ("centres", *steps)
        self._backend.run(steps, frames=None, masked=self._masked)
        self._converted = self._converted or "convert" in steps
        if "correlate" in steps or "fused" in steps:  # the correlations are new: so are the layers, or none
            self._layers_made = "layers" in steps

    # --- stages (public so benchmarks can time them; ``process`` runs them in order) ----------------------------
    def prepare(self, frames, target_disparity=None, *, centres=None, active=None) -> None:
        """Stage 0: ``load`` the frames, set the targets and compute the tile centres."""
        validate.targets(target_disparity, centres)
        self.load(frames)
        self.set_targets(target_disparity, centres=centres, active=active)
        if self._ideal:
            self._backend.run(("centres",), frames=None, masked=self._masked)
        self._ideal = False  # the centres are now in place for convert

    def convert(self) -> None:
        """Stage 1: padded frames and centres -> CLT tiles, finite and valid masks (needs the CLT tiles kept)."""
        self._need_clt("convert")
        self._run(("convert",))

    def correlate(self) -> None:
        """Stage 2: CLT tiles -> pair correlations (and the network layers for the quad's pairs)."""
        self._need_clt("correlate")
        self._run(("correlate", "layers"))

    def fused(self) -> None:
        """Stages 1 + 2 in one pass without the CLT tiles: padded frames and centres -> correlations, layers,
        finite and valid masks (what ``measure`` runs on a processor that does not keep the CLT tiles)."""
        self._run(("fused", "layers"))

    def _need_clt(self, stage: str) -> None:
        if self._buffers.clt is None:
            raise RuntimeError(f"{stage}: this processor does not keep the CLT tiles; build it with clt=True, "
                               "or run fused()")

    def texture(self) -> None:
        """Stage 3: CLT tiles -> RGBA texture image (needs ``textures=True`` at construction); converts the
        loaded frames at the current targets first unless that was the last thing done to them (band by band
        without ``clt=True``)."""
        if not self.textures:
            raise RuntimeError("texture: this processor was built without textures=True")
        if not self.keeps_clt:
            self._run(("convert_texture",))
        else:
            self._run(("texture",) if self._converted else ("convert", "texture"))
