"""The frame pipeline: raw frames of any rig in, disparity (+ confidence) and an RGBA texture out, on one device.

Per frame: the disparity engine (``tpnet_gpu.disparity``: coarse-to-fine cost-volume search, SGM over the tile
grid, sparse re-correlation) gives each tile's disparity; TPNET then reads the network layers at those
disparities (the quad's from the processor's kernel, zero-copy; any other rig's from its pair correlations, one
layer per direction group, ``tpnet_gpu.net.layers``) and predicts the final disparity, with weights trained for
the rig's layer lags (network.md §11: the shipped ones are picked by lags; a rig none fits runs without the
network, logged), and its context step (``net/context.py``, network.md §13) averages each tile with its
neighbours on the same surface; the texture is made at that disparity.
Frames are loaded once per frame. Buffers belong to the tile processors and the model and are allocated once per
frame size; results are views or new small tensors, valid until the next frame.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import PipelineConfig, TextureConfig, disparity_range
from tpnet_gpu.disparity import budget
from tpnet_gpu.disparity.checks import CROSS_CHECK_PX, cross_camera, cross_difference, windows_inside
from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.disparity.follow import REFRESH
from tpnet_gpu.disparity.results import DisparityResult
from tpnet_gpu.disparity.grid import grow
from tpnet_gpu.disparity.per_pixel import per_pixel
from tpnet_gpu.disparity.pixel_check import MIN_SUPPORT, fill_background, left_right, tile_answers
from tpnet_gpu.disparity.two_surface import Surfaces, measure_surfaces
from tpnet_gpu.io.paths import regular_file
from tpnet_gpu.net import infer
from tpnet_gpu.net.context import context_step
from tpnet_gpu.net.layers import NetworkLayers, lags_match
from tpnet_gpu.net.neighbours import CLUSTER_RADIUS
from tpnet_gpu.processor import TileProcessor

log = logging.getLogger(__name__)
# the pipeline's memory besides the engines' cost volumes, per frame pixel: peak RSS of `tpnet process` on a
# 4000x3000 mono pair searched to 16 px (volumes 0.2 GB) was 3.16 GB, 2-core Xeon, 2026-12-07 - frames, tile
# processors, textures, per-pixel maps, torch and Python
FRAME_BYTES_PER_PIXEL = 250.0


@dataclass(frozen=True)
class FrameResult:
    """One frame's results, torch tensors on the pipeline's device (valid until the next frame).

    Attributes:
        disparity: ``(tiles_y, tiles_x)`` final disparity, px (TPNET's after its context step where the pipeline
            has weights for its rig, ``Pipeline.weights``, else the engine's); NaN where the engine gave none (it
            trusted no measurement and had no clear first-stage answer on the tile's surface: grid.fill).
        confidence: ``(tiles_y, tiles_x)`` the engine's confidence (its final correlation peak's strength,
            scaled down on two-depth tiles; higher = surer), 0 = none (NaN tiles and tiles grid.fill gave);
            where the per-pixel check ran (``pixels_measured``), the share of the tile's window (half-sine
            weight, 0..1) whose checked pixels back the answer within 1 px, and ``disparity`` the window's mean
            of the checked, background-filled ``pixels``.
        two_depth: ``(tiles_y, tiles_x)`` bool: the tile's window straddles two depths (its neighbours'
            disparities span more than 1 px): flagged, not a surface to trust (grid.two_depth).
        initial: ``(tiles_y, tiles_x)`` the engine's disparities the network read its layers at (NaN = none).
        search: ``(tiles_y, tiles_x)`` the engine's first-stage answer (finite everywhere): where ``initial`` is
            NaN the network and the texture read the tile there.
        valid: ``(tiles_y, tiles_x)`` bool: the tile's windows were inside the image and finite, as the last pass
            read them (the texture's reads every tile; without textures, tiles that pass did not read are False:
            the network's reads the tiles within 2 of a measured tile, the engine's those still refined).
        texture: ``(channels, H, W)`` R, G, B (or Y), alpha at the final disparity, or None.
        tile_passes: tiles x cameras processed for the disparity, in full-resolution passes.
        surfaces: with ``PipelineConfig.two_surface``: ``Surfaces`` (foreground, background disparities and
            their weights, ``(tiles_y, tiles_x)`` each, NaN where the tile shows one surface), else None.
        pixels: with ``PipelineConfig.per_pixel``: ``(H, W)`` float32 disparity per pixel of the reference
            camera, px (NaN = none), else None.
        checked: ``(tiles_y, tiles_x)`` bool: the tiles the checks and the confidence filters kept
            (``PipelineConfig``); ``disparity`` is NaN elsewhere.
        pixels_measured: where the per-pixel left-right check ran (``per_pixel`` and ``cross_check``, the
            default for mono pairs): ``(H, W)`` bool, the pixels whose match in the other view answered back the
            same disparity; ``pixels`` elsewhere is the background fill (disparity.md §10). Else None.
        engine: the disparity engine's own ``DisparityResult`` (its tensors valid until the next frame): what
            ``process(frames, previous=...)`` follows on the next frame of a video.
        cross: the cross-check engine's ``DisparityResult`` (the other camera's view), or None without one.
    """

    disparity: torch.Tensor
    confidence: torch.Tensor
    two_depth: torch.Tensor
    initial: torch.Tensor
    valid: torch.Tensor
    texture: torch.Tensor | None
    search: torch.Tensor
    tile_passes: float
    surfaces: Surfaces | None = None
    pixels: torch.Tensor | None = None
    checked: torch.Tensor | None = None
    pixels_measured: torch.Tensor | None = None
    engine: DisparityResult | None = None
    cross: DisparityResult | None = None


class Pipeline:
    """Frames of ``height`` x ``width`` from a rig (default: the ideal quad).

    Args:
        cfa: Bayer pattern of the frames, or None for mono.
        rig: camera geometry (any number of cameras; a calibrated rig's tile centres are used).
        pairs: camera pairs to correlate (default: all pairs of the rig; the quad's 6).
        min_disparity, max_disparity: the range searched, px (default: 0 to the rig's disparity at
            ``EngineConfig.nearest_m``).
        weights: TPNET weights (default: the shipped ones trained for the rig's layer lags, none for a rig
            no shipped weights fit: the engine's result, logged as a warning). Weights trained for other lags
            are refused (``ValueError``).
        device: "cpu" or "cuda" (default cuda when present).
        backend: kernel language of the tile processors, "warp" or "taichi"; None: ``TileProcessor``'s default.

    Attributes:
        weights: the TPNET weights in use (a path), or None (no network: the disparity is the engine's).
        layers: the rig's ``NetworkLayers`` (its direction groups: ``layers.lags``).
    """

    def __init__(self, height: int, width: int, *, cfa: str | None = "GRBG", rig: Rig | None = None, pairs=None,
                 min_disparity: float | None = None, max_disparity: float | None = None, weights=None,
                 device: str | None = None, config: PipelineConfig = PipelineConfig(), backend: str | None = None):
        engine_config = config.engine
        self.config = config
        self._check_memory(height, width, rig, min_disparity, max_disparity, device)
        self.engine = DisparityEngine(height, width, rig=rig, pairs=pairs, cfa=cfa, min_disparity=min_disparity,
                                      max_disparity=max_disparity, config=engine_config,
                                      device=device, backend=backend, textures=config.textures)
        tp = self.engine.tp
        self.device = tp.torch_device
        self.grid = self.engine.grid
        self.model = None
        self.network_tp = None
        # the network passes' tile masks (grid.grow's buffers), made once
        self._near = torch.zeros(self.grid, dtype=torch.bool, device=self.device)
        self._scratch = torch.zeros_like(self._near)
        self.layers = NetworkLayers(self.engine.rig.offsets, tp.pairs, self.device)
        if config.method == "engine" and weights is not None:
            raise ValueError(f"weights: {weights} given with PipelineConfig(method='engine'), which runs no network")
        self.weights = self._weights(weights, tp.colours) if config.method != "engine" else None
        self._checks(height, width, cfa, pairs, engine_config, device, backend)
        if self.weights is not None:
            net_config = infer.correlation(self.weights)
            same = net_config.resolved(tp.colours) == tp.config
            self.network_tp = tp if same else TileProcessor(
                height, width, camera_offsets=self.engine.rig.offsets_array(), pairs=tp.pairs, cfa=cfa,
                config=net_config, textures=config.textures, texture_config=TextureConfig(), device=str(tp.device),
                backend=backend)
            self.model = infer.load(self.weights, device=self.device)
            self._infer = infer.infer  # an attribute, so the pipeline bench can time the network's share
        log.info("pipeline %dx%d on %s: %d cameras, disparity %g .. %g px, weights %s", width, height, self.device,
                 self.engine.rig.cams, self.engine.d_min, self.engine.d_max, self.weights)

    def _check_memory(self, height, width, rig, min_disparity, max_disparity, device) -> None:
        """Refuse a frame and range whose engines (the cross-check's too) need more than the budget, before either
        is made (``disparity.budget``; the range's own checks come first)."""
        cfg = self.config
        try:
            view = rig if isinstance(rig, Rig) else Rig(width=width, height=height)
            d_min, d_max = disparity_range(min_disparity, max_disparity, view, cfg.engine.nearest_m)
        except (ValueError, TypeError):
            return  # the engine refuses the frame, the rig or the range, in its own order, naming them
        if (view.width, view.height) != (width, height):
            return
        engines = 2 if cfg.cross_check or (cfg.cross_check is None and view.cams == 2) else 1
        where = device or ("cuda" if torch.cuda.is_available() else "cpu")
        budget.check(height, width, d_min, d_max, cfg.engine, where, engines,
                     frame_bytes=FRAME_BYTES_PER_PIXEL * height * width)

    def _checks(self, height, width, cfa, pairs, engine_config, device, backend) -> None:
        """The cross-check's engine (``PipelineConfig.cross_check``) and the per-pixel step's cameras."""
        cfg, rig = self.config, self.engine.rig
        self.offsets = rig.offsets_array()  # (cams, 2) on the host: read once, not per frame
        two = rig.cams == 2
        self.cross_engine, self.cross_cam = None, cross_camera(self.offsets)
        self.cross_offset = tuple(float(v) for v in self.offsets[self.cross_cam])
        if cfg.cross_check or (cfg.cross_check is None and two):
            self.cross_engine = DisparityEngine(height, width, rig=rig.referenced_to(self.cross_cam), pairs=pairs,
                                                cfa=cfa, min_disparity=self.engine.d_min,
                                                max_disparity=self.engine.d_max, config=engine_config,
                                                device=device, backend=backend)
        at_reference = np.nonzero(np.linalg.norm(self.offsets, axis=1) < 1e-9)[0]
        possible = cfa is None and at_reference.size > 0
        if cfg.per_pixel and not possible:
            raise ValueError("per_pixel: needs mono frames (cfa None) and a rig with a camera at the reference "
                             f"(offset (0, 0)); got cfa {cfa!r} and offsets {rig.offsets_array().tolist()}")
        self.reference_cam = int(at_reference[0]) if at_reference.size else None
        self.per_pixel = bool(cfg.per_pixel) or (cfg.per_pixel is None and possible and two)

    def _weights(self, weights, colours: int) -> Path | None:
        """The weights for this rig's layer lags and these frames' colours: ``weights`` if they were trained for
        them (else ValueError), or the shipped ones that were, or None (logged: the engine's result)."""
        lags = [list(v) for v in self.layers.lags]
        if weights is not None:
            regular_file(weights, "weights", "weights file (from `tpnet train`)")
            if not lags_match(infer.lags(weights), self.layers.lags):
                raise ValueError(f"weights: {weights} were trained for a rig whose layers have lags "
                                 f"{[list(v) for v in infer.lags(weights)]}; this pipeline's rig has {lags} "
                                 f"(train weights for it: `tpnet dataset --rig` then `tpnet train`)")
            trained = infer.correlation(weights).colour_weights
            if not infer.fits_colours(weights, colours):
                raise ValueError(f"weights: {weights} were trained on frames of {len(trained)} colours; these "
                                 f"frames have {colours} (cfa None: mono)")
            return Path(weights)
        asked = self.config.method == "tpnet"
        found = infer.shipped_for(self.layers.lags, colours, requested=asked)
        if found is None and asked:
            raise ValueError(f"method: 'tpnet' asks for the network, but no shipped weights fit this rig (layer lags "
                             f"{lags}) and {colours}-colour frames (train them: `tpnet dataset --rig` then "
                             f"`tpnet train`, and pass --weights)")
        kept = infer.shipped_for(self.layers.lags, colours, requested=True) if found is None else None
        if kept is not None:
            log.warning("TPNET weights for this rig and %d-colour frames ship on request only (--method tpnet, "
                        "%s): %s; the disparity is the engine's", colours, kept.name, infer.on_request(kept))
            return None
        if found is None:
            log.warning("no shipped TPNET weights for this rig (layer lags %s) and %d-colour frames: the disparity "
                        "is the engine's", lags, colours)
            return None
        return found

    def process(self, frames, previous: FrameResult | DisparityResult | None = None) -> FrameResult:
        """Frames ``(cams, H, W)`` (torch on any device or NumPy, any real dtype; black level subtracted).
        ``previous``: the frame before's result (a video): the engines follow it instead of searching the whole
        range (``disparity.follow``; ``stream(follow=True)``) - a ``FrameResult`` both engines (the
        cross-check's follows its ``cross``), its ``engine`` (a ``DisparityResult``) the main one only."""
        cfg = self.config
        previous, self._previous_cross = ((previous.engine, previous.cross) if isinstance(previous, FrameResult)
                                          else (previous, None))
        self._cross = None  # the cross-check engine's result, when it runs
        result = self.engine.run(frames, previous)
        measured = torch.isfinite(result.disparity)
        initial = result.disparity
        disparity = initial
        tp = self.engine.tp
        if self.model is not None:
            tp = self.network_tp
            if tp is not self.engine.tp:
                tp.load(self.engine.normalise(frames, out=tp.staging))
            # tiles the refinement left unmeasured are read at the first stage's answer (always finite)
            target = torch.where(measured, initial, result.search)
            for done in range(cfg.network_passes):
                # only the tiles a measured tile's final answer depends on: stage 2 reads CLUSTER_RADIUS tiles
                # around, once per pass still to run (the others' answers are NaN in the result; same values)
                near = grow(measured, CLUSTER_RADIUS * (cfg.network_passes - done), self._near, self._scratch)
                layers = self.layers.of(self.engine.measure_at(tp, target, active=near))
                target = self._infer(self.model, layers, target, grid=self.grid)
            # the context step after the last pass (net/context.py: between passes the next pass undid it)
            disparity = context_step(torch.where(measured, target, torch.full_like(target, float("nan"))),
                                     result.strength)
        texture = None
        if cfg.textures:  # shift-corrected at the final disparity
            self.engine.set_targets(tp, torch.where(measured, disparity, result.search))
            tp.texture()  # converts at these targets (the measuring passes were fused, without CLT tiles)
            texture = tp.result.texture
            texture[:-1] /= self.engine.scale  # colours back in the frames' units (alpha is unitless)
        confidence = torch.where(measured, result.confidence, torch.zeros_like(result.confidence))
        valid, surfaces = tp.result.valid.view(self.grid), None
        if cfg.two_surface:  # its passes overwrite the engine's processor's views: keep the mask first
            valid = valid.clone()
            surfaces = measure_surfaces(self.engine, disparity)
        pixels = pixels_measured = other = None
        engine_confidence = confidence
        if self.per_pixel:  # from every answer: a tile the checks drop can still be a right pixel's candidate
            staging = self.engine.tp.staging  # the frames as the engine normalised them (ZNCC ignores the scale)
            pixels, _ = per_pixel(staging[self.reference_cam], staging[self.cross_cam], disparity,
                                  offset=self.cross_offset)
            if self.cross_engine is not None:  # the left-right check per pixel, and tiles from its pixels
                other = self.cross_engine.run(staging, self._previous_cross)
                back = tuple(-v for v in self.cross_offset)  # the reference camera, seen from the other one
                other_pixels, _ = per_pixel(staging[self.cross_cam], staging[self.reference_cam], other.disparity,
                                            offset=back)
                pixels_measured = left_right(pixels, other_pixels, self.cross_offset)
                pixels = fill_background(torch.where(pixels_measured, pixels, torch.full_like(pixels, float("nan"))),
                                         self.cross_offset)
                disparity, confidence = tile_answers(pixels, pixels_measured, disparity)
        passes, keep = result.tile_passes, measured
        if self.cross_engine is not None or cfg.min_confidence > 0 or cfg.keep_fraction < 1:
            keep = self._keep(disparity, confidence, other, engine_confidence)
            disparity = torch.where(keep, disparity, torch.full_like(disparity, float("nan")))
            confidence = torch.where(keep, confidence, torch.zeros_like(confidence))
            passes += self._cross_passes
        return FrameResult(disparity, confidence, result.two_depth, initial, valid, texture, result.search,
                           passes, surfaces, pixels, keep, pixels_measured, result, self._cross)

    def _keep(self, disparity: torch.Tensor, confidence: torch.Tensor, other, tiebreak: torch.Tensor) -> torch.Tensor:
        """``(ty, tx)`` bool: the tiles ``PipelineConfig``'s checks and filters keep (see there); sets
        ``self._cross_passes`` (the cross-check's tile passes, 0 without it) and ``self._cross`` (its result).
        ``other``: the cross-check's engine result where the per-pixel check ran (its tiles' confidence is their
        support), else None;
        ``tiebreak``: orders tiles of equal confidence for ``keep_fraction`` (the engine's confidence)."""
        cfg = self.config
        keep = torch.isfinite(disparity)
        self._cross_passes = 0.0
        size = (self.engine.tp.height, self.engine.tp.width)
        if other is not None:
            self._cross, self._cross_passes = other, other.tile_passes
            keep = keep & windows_inside(disparity, self.offsets, size) & (confidence >= MIN_SUPPORT)
        elif self.cross_engine is not None:
            # from the frames the engine already staged on the device (not the caller's again: no second host
            # copy and validation; its scale comes out 1)
            other = self.cross_engine.run(self.engine.tp.staging, self._previous_cross)
            self._cross, self._cross_passes = other, other.tile_passes
            keep = keep & windows_inside(disparity, self.offsets, size) & (
                cross_difference(disparity, other.disparity, self.cross_offset) <= CROSS_CHECK_PX)
        if cfg.min_confidence > 0:
            keep = keep & (confidence >= cfg.min_confidence)
        if cfg.keep_fraction < 1 and bool(keep.any()):
            keep = _most_confident(keep, confidence, tiebreak, cfg.keep_fraction)
        return keep

    def stream(self, frames: Iterable, *, follow: bool = False) -> Iterator[FrameResult | FrameError]:
        """Process an iterable of frames (e.g. a camera) one by one; each result is valid until the next.

        One result per frame, in order: a frame that ``process`` refuses or fails on (a wrong shape, a bad
        dtype, ...) gives a ``FrameError`` carrying the exception, and the stream goes on with the next frame
        (whose result is what it would have been without the bad one). A reader that could not read a frame
        may yield the exception in its place (``io.sequence.read_frames``): that frame's ``FrameError``. Errors
        raised by the iterable itself end it.
        ``follow``: a video - each frame's engine starts from the frame before's answers (``disparity.follow``),
        with the full search on the first frame, every ``follow.REFRESH``-th and the one after a bad frame."""
        previous, since, kept = None, 0, None
        for index, item in enumerate(frames):
            if since >= REFRESH:
                previous, since = None, 0
            try:
                if isinstance(item, Exception):
                    raise item
                result = self.process(item, previous if follow else None)
            except Exception as exc:  # noqa: BLE001 - one bad frame must not end a camera's stream (issue 16)
                previous, since = None, 0
                yield FrameError(index, exc)
                continue
            if follow:  # the engines' answers kept past the next frame's run (they reuse their buffers)
                kept = {name: _kept(getattr(result, name), (kept or {}).get(name)) for name in ("engine", "cross")}
                previous = replace(result, **kept)
            since += 1
            yield result


def _kept(result: DisparityResult | None, copy: DisparityResult | None) -> DisparityResult | None:
    """``result``'s tensors in ``copy`` (written in place), or in a copy made now (the first frame); its other
    fields (passes, motion) as they are."""
    if result is None:
        return None
    tensors = [f.name for f in fields(DisparityResult) if torch.is_tensor(getattr(result, f.name))]
    if copy is None:
        return replace(result, **{name: getattr(result, name).clone() for name in tensors})
    for name in tensors:
        getattr(copy, name).copy_(getattr(result, name))
    return replace(result, **{name: getattr(copy, name) for name in tensors})


def _most_confident(keep: torch.Tensor, confidence: torch.Tensor, tiebreak: torch.Tensor,
                    fraction: float) -> torch.Tensor:
    """``keep (ty, tx)`` cut to its ``ceil(fraction * n)`` most confident tiles, equal confidences ordered by
    ``tiebreak`` (the per-pixel check's confidence is a share of a window: whole tiles tie at 1)."""
    index = torch.nonzero(keep.reshape(-1)).squeeze(1)
    order = torch.argsort(tiebreak.reshape(-1)[index], descending=True, stable=True)
    order = order[torch.argsort(confidence.reshape(-1)[index][order], descending=True, stable=True)]
    take = int(np.ceil(fraction * index.numel()))
    out = torch.zeros_like(keep).reshape(-1)
    out[index[order[:take]]] = True
    return out.reshape(keep.shape)


@dataclass(frozen=True)
class FrameError:
    """A frame of ``Pipeline.stream`` that gave no result: its place in the stream and the exception raised."""

    index: int
    error: Exception


def load_frames(paths, cfa: str | None = None) -> tuple[np.ndarray, str]:
    """Black-subtracted float32 frames ``(cams, H, W)`` and their CFA from a scene folder (one path) or one raw
    file per camera (DNG or anything LibRaw reads; TIFF needs ``cfa``)."""
    from tpnet_gpu.io import rawio  # noqa: PLC0415
    from tpnet_gpu.scenes.folder import load  # noqa: PLC0415

    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    if len(paths) == 1 and paths[0].is_dir():
        scene = load(paths[0])
        return scene.frames, scene.cfa
    frames = rawio.read_frames(paths, cfa=cfa)
    return rawio.stack_normalised(frames), frames[0].cfa
