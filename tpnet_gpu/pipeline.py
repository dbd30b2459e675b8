"""The frame pipeline: raw quad frames in, disparity (+ confidence) and an RGBA texture out, on one device.

Per frame, everything stays on the pipeline's device (no host round trip): a coarse sweep of target
disparities measured by the tile processor and the on-device centre-of-mass estimator (strips,
geometry_and_lma.md C.1-C.3) gives initial targets; a few re-correlation passes refine them; TPNET reads the
tile processor's layers at those targets (zero-copy) and predicts the disparity; the texture is made at the
predicted disparity.
Buffers belong to the two tile processors and the model and are allocated once per frame size; results are
views of them, overwritten by the next frame.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
import torch

from tpnet_gpu.baseline.estimate import BASELINE_CORRELATION
from tpnet_gpu.baseline.strips import StripParams, centre_of_mass, combine_strips, pair_strips
from tpnet_gpu.config import TextureConfig
from tpnet_gpu.processor import TileProcessor


@dataclass(frozen=True)
class PipelineConfig:
    """``sweep``: initial target disparities tried (px); ``refine_passes`` of centre-of-mass re-correlation;
    ``trust``: largest residual believed (px); ``min_strength``: weakest peak taken as a measurement (as the
    baseline's refine_min_strength); ``network_passes``: TPNET passes, each re-correlating at the previous
    one's disparity; ``textures``: make the RGBA texture."""

    sweep: tuple = (0.0, 6.0, 12.0, 18.0, 24.0, 30.0, 36.0, 42.0)
    refine_passes: int = 2
    trust: float = 4.0
    min_strength: float = 0.1
    network_passes: int = 1
    textures: bool = True

    def __post_init__(self):
        if not isinstance(self.network_passes, int) or self.network_passes < 1:
            raise ValueError(f"network_passes: expected an int >= 1, got {self.network_passes!r}")


@dataclass(frozen=True)
class FrameResult:
    """One frame's results, torch tensors on the pipeline's device (views, overwritten by the next frame).

    Attributes:
        disparity: ``(tiles_y, tiles_x)`` TPNET disparity, px (NaN where no tile measurement was possible).
        confidence: ``(tiles_y, tiles_x)`` strength of the correlation peak at the refined target, 0 = none.
        initial: ``(tiles_y, tiles_x)`` the refined targets the network read its layers at (NaN = none).
        valid: ``(tiles_y, tiles_x)`` bool: the tile's windows were inside the image and finite.
        texture: ``(4, H, W)`` R, G, B, alpha at the network's disparity, or None.
    """

    disparity: torch.Tensor
    confidence: torch.Tensor
    initial: torch.Tensor
    valid: torch.Tensor
    texture: torch.Tensor | None


class Pipeline:
    """Frames of ``height`` x ``width`` from a quad with the ideal geometry (``cfa`` Bayer mosaics).

    Args:
        weights: TPNET weights (default: the shipped ones).
        device: "cpu" or "cuda" (default cuda when present).
        backend: kernel language of the tile processors, "warp" or "taichi"; None: ``TileProcessor``'s default
            (Taichi on the CPU, Warp on CUDA).
    """

    def __init__(self, height: int, width: int, *, cfa: str = "GRBG", weights=None, device: str | None = None,
                 config: PipelineConfig = PipelineConfig(), backend: str | None = None):
        from tpnet_gpu.net import infer  # noqa: PLC0415 - torch model loading on use

        self.config = config
        self.measure = TileProcessor(height, width, cfa=cfa, config=BASELINE_CORRELATION, device=device,
                                     backend=backend)
        self.network_tp = TileProcessor(height, width, cfa=cfa, config=infer.correlation(weights),
                                        textures=config.textures, texture_config=TextureConfig(),
                                        device=str(self.measure.device), backend=backend)
        self.device = self.measure.torch_device
        self.grid = (self.measure.tiles_y, self.measure.tiles_x)
        self.model = infer.load(weights, device=self.device)
        self._infer = infer.infer
        self._strip_params = StripParams()
        shape = self.grid
        self._target = torch.zeros(shape, device=self.device)
        self._best_strength = torch.zeros(shape, device=self.device)
        self._best_target = torch.zeros(shape, device=self.device)

    def _residual(self, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Centre-of-mass residual and strength ``(ty, tx)`` of the loaded frame at ``target``, on the device."""
        corr = self.measure.measure(target).corr
        com = centre_of_mass(combine_strips(pair_strips(corr), self._strip_params.corr_offset), self._strip_params)
        return com.disparity.reshape(self.grid).to(torch.float32), com.strength.reshape(self.grid).to(torch.float32)

    def process(self, frames) -> FrameResult:
        """Frames ``(4, H, W)`` (torch on any device or NumPy, any real dtype; black level subtracted)."""
        cfg = self.config
        best_t, best_s, target = self._best_target, self._best_strength, self._target
        best_t.fill_(float("nan"))
        best_s.zero_()
        self.measure.load(frames)  # once per frame; every pass below measures it at new targets
        for value in cfg.sweep:
            target.fill_(value)
            residual, strength = self._residual(target)
            better = (torch.isfinite(residual) & (residual.abs() <= cfg.trust) & (strength >= cfg.min_strength)
                      & (strength > best_s))
            best_t.copy_(torch.where(better, target + residual, best_t))
            best_s.copy_(torch.where(better, strength, best_s))
        target.copy_(torch.nan_to_num(best_t, nan=0.0))
        measured = torch.isfinite(best_t)
        strength = best_s
        for _ in range(cfg.refine_passes):
            residual, strength = self._residual(target)
            step = torch.isfinite(residual) & (residual.abs() <= cfg.trust) & measured
            target.copy_(torch.where(step, target + residual, target))
        initial = torch.where(measured, target, torch.full_like(target, float("nan")))
        tp = self.network_tp
        disparity = target
        tp.load(frames)
        for _ in range(cfg.network_passes):
            disparity = self._infer(self.model, tp.measure(disparity).layers, disparity, grid=self.grid)
        disparity = torch.where(measured, disparity, torch.full_like(disparity, float("nan")))
        if cfg.textures:  # shift-corrected at the network's disparity
            tp.set_targets(torch.nan_to_num(disparity, nan=0.0))
            tp.convert()
            tp.texture()
        confidence = torch.where(measured, strength, torch.zeros_like(strength))
        return FrameResult(disparity, confidence, initial, tp.result.valid.view(self.grid), tp.result.texture)

    def stream(self, frames: Iterable) -> Iterator[FrameResult]:
        """Process an iterable of frames (e.g. a camera) one by one; each result is valid until the next."""
        for item in frames:
            yield self.process(item)


def load_frames(paths, cfa: str | None = None) -> tuple[np.ndarray, str]:
    """Black-subtracted float32 frames ``(cams, H, W)`` and their CFA from a scene folder (one path) or one raw
    file per camera (DNG or anything LibRaw reads; TIFF needs ``cfa``)."""
    from pathlib import Path  # noqa: PLC0415

    from tpnet_gpu import rawio  # noqa: PLC0415
    from tpnet_gpu.scenes.folder import load  # noqa: PLC0415

    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    if len(paths) == 1 and paths[0].is_dir():
        scene = load(paths[0])
        return scene.frames, scene.cfa
    frames = rawio.read_frames(paths, cfa=cfa)
    return rawio.stack_normalised(frames), frames[0].cfa
