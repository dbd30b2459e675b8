"""Pair peaks of one frame for calibration (docs/calibration.md §2), with the disparity engine's processor (its
frame scaling, correlation settings and rig geometry: ``DisparityEngine.measure_at``; no second tile
processor).

The engine's own search reads each pair along its axis; a misaligned rig moves the peaks across the axes by up to
twice the frame-edge misalignment, and at 2.5 px the engine's disparities were wrong by 10 px (median, a
320x240 random scene). So each tile's disparity is found from the full 2-D peaks instead: uniform targets every
``SWEEP_STEP`` px over the engine's range, the target whose pairs' peaks are jointly strongest, then
``REFINE_PASSES`` re-correlations at the disparity the peaks' along-axis components give (least squares over the
pairs). The last pass's peaks are the observations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tpnet_gpu.calibration import model
from tpnet_gpu.calibration.lma import Observations
from tpnet_gpu.calibration.peaks import REACH, pair_peaks
from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity.engine import DisparityEngine

SWEEP_STEP = 3.0  # px: with the +-REACH search, a peak up to 1.5 px along and ~4.5 px across an axis is seen
REFINE_PASSES = 2


@dataclass(frozen=True)
class Frame:
    """One frame to calibrate from: ``frames (cams, H, W)`` (black level removed), its Bayer ``cfa`` (None: mono)."""

    frames: np.ndarray
    cfa: str | None = "GRBG"


def tile_grid_centres(rig: Rig) -> np.ndarray:
    """``(tiles, 2)`` virtual-camera centres (8 tx + 4, 8 ty + 4) in the processor's tile order."""
    ty, tx = np.meshgrid(np.arange(rig.height // 8), np.arange(rig.width // 8), indexing="ij")
    return np.stack([8.0 * tx + 4.0, 8.0 * ty + 4.0], axis=-1).reshape(-1, 2)


def engine_for(frame: Frame, rig: Rig, device=None, backend=None) -> DisparityEngine:
    """A disparity engine for ``frame`` with ``rig``'s geometry, the frame scaled and loaded."""
    height, width = frame.frames.shape[1:]
    engine = DisparityEngine(height, width, rig=rig, cfa=frame.cfa, device=device, backend=backend)
    engine.tp.load(engine.normalise(frame.frames))
    return engine


def pair_directions(rig: Rig, pairs) -> np.ndarray:
    """``(P, 2)``: r_b - r_a, the lag (times minus the residual disparity) each pair's peak moves along."""
    r = rig.offsets_array()
    return np.stack([r[b] - r[a] for a, b in pairs])


def _peaks(engine: DisparityEngine, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Every tile's pair peaks ``(tiles, P, 2)`` and their mean strength ``(tiles,)`` (-inf where a pair has none)."""
    lags, strength = pair_peaks(engine.measure_at(engine.tp, target.reshape(engine.grid), layers=False).corr.double())
    lags = torch.where(lags.abs().amax(dim=-1, keepdim=True) < REACH, lags, torch.nan)  # rim maxima: no peak
    finite = torch.isfinite(lags).all(dim=-1).all(dim=-1)
    return lags, torch.where(finite, strength.mean(dim=-1), torch.full_like(strength[:, 0], -float("inf")))


def tile_disparities(engine: DisparityEngine, rig: Rig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(disparity (tiles,), lags (tiles, P, 2), strength (tiles,))`` from the 2-D peaks (module docstring)."""
    tiles = engine.tp.tiles
    best = torch.full((tiles,), -float("inf"), dtype=torch.float64)
    target = torch.zeros(tiles, dtype=torch.float64)
    for t in np.arange(engine.d_min, engine.d_max + SWEEP_STEP, SWEEP_STEP):
        _, strength = _peaks(engine, torch.full((tiles,), float(t)))
        target = torch.where(strength > best, float(t), target)
        best = torch.maximum(best, strength)
    u = torch.as_tensor(pair_directions(rig, engine.tp.pairs))
    for _ in range(REFINE_PASSES + 1):
        lags, strength = _peaks(engine, target.float())
        if _ == REFINE_PASSES:
            break
        step = -(lags * u).sum(dim=(-1, -2)) / (u * u).sum()
        target = torch.where(torch.isfinite(step), target + step, target)
    return target, lags, strength


def observe(frame: Frame, rig: Rig, *, device=None, backend=None) -> Observations:
    """The measured pair peaks of ``frame``'s tiles that are strong enough (``EngineConfig.min_strength``), with the
    geometry of ``rig``."""
    engine = engine_for(frame, rig, device, backend)
    disparity, lags, strength = tile_disparities(engine, rig)
    index = torch.nonzero(strength >= engine.config.min_strength)[:, 0]
    centre = tile_grid_centres(rig)[index.numpy()]
    d = disparity[index].numpy()
    reference = model.pair_differences(rig.port_coordinates(centre, d), engine.tp.pairs)
    return Observations(centre, d, lags[index].cpu().numpy(), reference)
