"""Pair geometry of any rig, and the correlation sampled along each pair's disparity axis (geometry_and_lma.md B.2,
B.3; tile_processor.md §6.4).

Convention: camera i sees a centre-camera point c at c - d r_i (r_i its offset in baselines), so pair (a, b)'s
correlation of a tile measured at target T with true disparity T + e peaks at lag ``-e v`` with
``v = r_b - r_a`` (x, y; lag units = pixels). Directions and lengths come from the offsets, never from quad tables.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu import tables
from tpnet_gpu.layout import CORR_RADIUS, TILE_SIZE


def pair_vectors(offsets, pairs) -> np.ndarray:
    """``(pairs, 2)`` lag per unit residual disparity (x, y): r_second - r_first."""
    r = np.asarray(offsets, dtype=np.float64)
    return np.array([r[b] - r[a] for a, b in pairs])


def window_overlap(shift) -> np.ndarray:
    """Relative correlation amplitude of two 16-px half-sine windows shifted by ``shift`` px (any shape):
    sum_n w(n) w(n + k) / sum_n w(n)^2, linearly interpolated, 0 beyond the window."""
    w = tables.half_sine(np.arange(TILE_SIZE))
    k = np.arange(TILE_SIZE)
    table = np.array([np.dot(w[: TILE_SIZE - j], w[j:]) for j in k]) / np.dot(w, w)
    return np.interp(np.abs(np.asarray(shift, dtype=np.float64)), k, table, right=0.0)


class AxisSampler:
    """Samples pair correlations ``(T, P, 15, 15)`` at disparity offsets ``e`` along each pair's axis (bilinear),
    divided by the windows' overlap at that lag (the peak of a true shift loses amplitude as the windows overlap
    less - without this, off-centre lags lose to weaker centred ones). NaN where a lag falls outside +-7."""

    def __init__(self, offsets, pairs, device):
        v = pair_vectors(offsets, pairs)
        self.vectors = torch.as_tensor(v, dtype=torch.float32, device=device)  # (P, 2)
        self.reach = float(CORR_RADIUS / np.abs(v).max())  # |e| the lags of every pair reach
        k = np.linspace(0.0, TILE_SIZE, 4 * TILE_SIZE + 1)
        self._ov = torch.as_tensor(window_overlap(k), dtype=torch.float32, device=device)

    def _overlap(self, shift: torch.Tensor) -> torch.Tensor:
        pos = (shift.abs() / TILE_SIZE * (len(self._ov) - 1)).clamp(max=len(self._ov) - 1)
        lo = pos.floor().long().clamp(max=len(self._ov) - 2)
        frac = pos - lo
        return self._ov[lo] * (1 - frac) + self._ov[lo + 1] * frac

    def sample(self, corr: torch.Tensor, e: torch.Tensor, mode: str = "bilinear") -> torch.Tensor:
        """``(T, P, E)`` overlap-normalised pair correlations at offsets ``e`` ``(T, E)`` or ``(E,)`` (px).
        ``mode`` "bicubic" for sub-pixel peaks (bilinear samples of a sharp peak pull its parabola toward whole
        lags: +0.19 px median on a rendered plane at 3.3 px, 0.03 bicubic), "bilinear" for cost volumes."""
        tiles, npairs = corr.shape[:2]
        shared = e.dim() == 1  # the same offsets for every tile: the overlap is one (P, E) table
        lag = -(e[None, :] if shared else e)[:, None, :, None] * self.vectors[None, :, None, :]  # (T|1, P, E, 2)
        grid = (lag.expand(tiles, -1, -1, -1) / CORR_RADIUS).reshape(tiles * npairs, 1, -1, 2)
        values = F.grid_sample(corr.reshape(tiles * npairs, 1, 2 * CORR_RADIUS + 1, 2 * CORR_RADIUS + 1).float(),
                               grid, mode=mode, padding_mode="zeros", align_corners=True)
        values = values.reshape(tiles, npairs, -1)
        overlap = (self._overlap(lag[..., 0]) * self._overlap(lag[..., 1])).clamp(min=0.05)
        inside = (lag.abs() <= CORR_RADIUS + 1e-4).all(dim=-1)
        return torch.where(inside, values / overlap, torch.full_like(values, float("nan")))


# Offset of the geometric mean over pairs: small, so a candidate one pair direction disagrees with is suppressed
# (24 rendered tuning scenes, flat tiles gross: 0.3 -> 1.14 %, 0.1 -> 1.04 %, 0.03 -> 1.00 %, 0.01 -> 1.03 %).
COMBINE_OFFSET = 0.03


def combine_pairs(values: torch.Tensor, offset: float = COMBINE_OFFSET) -> torch.Tensor:
    """``(T, E)``: geometric mean over pairs of max(value + offset, 0), minus ``offset`` (the pairs must agree:
    a false peak of one direction is suppressed by the others); NaN pairs are left out, all-NaN gives NaN."""
    count = torch.isfinite(values).sum(dim=1)
    # a NaN pair contributes log(1) = 0 to the sum; one temporary, the rest in place (this runs on every pass)
    logs = torch.nan_to_num(values, nan=1.0 - offset).add_(offset).clamp_(min=1e-6).log_()
    out = torch.exp(logs.sum(dim=1) / count.clamp(min=1)) - offset
    return torch.where(count > 0, out, torch.full_like(out, float("nan")))
