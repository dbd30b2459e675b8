"""Pair geometry of any rig, and the correlation sampled along each pair's disparity axis (geometry_and_lma.md B.2,
B.3; tile_processor.md §6.4).

Convention: camera i sees a centre-camera point c at c - d r_i (r_i its offset in baselines), so pair (a, b)'s
correlation of a tile measured at target T with true disparity T + e peaks at lag ``-e v`` with
``v = r_b - r_a`` (x, y; lag units = pixels). Directions and lengths come from the offsets, never from quad tables.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu import tables
from tpnet_gpu.layout import CORR_RADIUS, TILE_SIZE


def pair_vectors(offsets, pairs) -> np.ndarray:
    """``(pairs, 2)`` lag per unit residual disparity (x, y): r_second - r_first."""
    r = np.asarray(offsets, dtype=np.float64)
    return np.array([r[b] - r[a] for a, b in pairs])


def default_pairs(offsets) -> tuple:
    """The pairs a rig correlates unless told otherwise: the quad's 6 in the spec's order for the quad's offsets,
    else every pair (a, b), a < b."""
    r = np.asarray(offsets, dtype=np.float64)
    if r.shape == (4, 2) and np.allclose(r, tables.QUAD_OFFSETS):
        return tables.QUAD_PAIRS
    return tuple((a, b) for a in range(len(r)) for b in range(a + 1, len(r)))


def window_overlap(shift) -> np.ndarray:
    """Relative correlation amplitude of two 16-px half-sine windows shifted by ``shift`` px (any shape):
    sum_n w(n) w(n + k) / sum_n w(n)^2, linearly interpolated, 0 beyond the window."""
    w = tables.half_sine(np.arange(TILE_SIZE))
    k = np.arange(TILE_SIZE)
    table = np.array([np.dot(w[: TILE_SIZE - j], w[j:]) for j in k]) / np.dot(w, w)
    return np.interp(np.abs(np.asarray(shift, dtype=np.float64)), k, table, right=0.0)


class WindowOverlap:
    """``window_overlap`` on the device: ``overlap(shift)`` for a tensor of shifts (px, any shape), linearly
    interpolated in a quarter-pixel table."""

    def __init__(self, device):
        k = np.linspace(0.0, TILE_SIZE, 4 * TILE_SIZE + 1)
        self._table = torch.as_tensor(window_overlap(k), dtype=torch.float32, device=device)

    def __call__(self, shift: torch.Tensor) -> torch.Tensor:
        table = self._table
        pos = (shift.abs() / TILE_SIZE * (len(table) - 1)).clamp(max=len(table) - 1)
        lo = pos.floor().long().clamp(max=len(table) - 2)
        frac = pos - lo
        return table[lo] * (1 - frac) + table[lo + 1] * frac


class AxisSampler:
    """Samples pair correlations ``(T, P, 15, 15)`` at disparity offsets ``e`` along each pair's axis (bilinear),
    divided by the windows' overlap at that lag (the peak of a true shift loses amplitude as the windows overlap
    less - without this, off-centre lags lose to weaker centred ones). NaN where a lag falls outside +-7."""

    def __init__(self, offsets, pairs, device):
        v = pair_vectors(offsets, pairs)
        self.vectors = torch.as_tensor(v, dtype=torch.float32, device=device)  # (P, 2)
        self.reach = float(CORR_RADIUS / np.abs(v).max())  # |e| the lags of every pair reach
        self._overlap = WindowOverlap(device)

    def sample(self, corr: torch.Tensor, e: torch.Tensor, mode: str = "bilinear", *, vectors=None,
               origin=None, normalise: bool = True) -> torch.Tensor:
        """``(T, P, E)`` overlap-normalised pair correlations at offsets ``e`` ``(T, E)`` or ``(E,)`` (px).
        ``mode`` "bicubic" for sub-pixel peaks (bilinear samples of a sharp peak pull its parabola toward whole
        lags: +0.19 px median on a rendered plane at 3.3 px, 0.03 bicubic), "bilinear" for cost volumes.
        ``vectors (P, 2)``: read along these lags per px instead of the pairs' (e.g. across a pair's axis), from
        the lags ``origin (T, P, 2)`` instead of 0; ``normalise`` False: the raw correlations (no division by
        the overlap - it suits a peak at the sampled lag, not another peak's flank there)."""
        tiles, npairs = corr.shape[:2]
        vectors = self.vectors if vectors is None else vectors
        e = e[None, :] if e.dim() == 1 else e  # the same offsets for every tile: one (1, P, E) lag table
        lag = -e[:, None, :, None] * vectors[None, :, None, :]  # (T|1, P, E, 2)
        if origin is not None:
            lag = lag + origin[:, :, None, :]
        grid, divisor = self._lag_terms(lag, normalise)
        return self._read(corr, grid.expand(tiles, -1, -1, -1), divisor, mode)

    def table(self, e: torch.Tensor) -> LagTable:
        """The grid and divisors of ``sample`` at each row of offsets ``e (K, E)`` (px), made once, for
        ``sample_rows``."""
        return LagTable(*self._lag_terms(-e[:, None, :, None] * self.vectors[None, :, None, :], True))

    def uniform(self, e: torch.Tensor, tiles: int) -> LagTable:
        """The table of ``sample`` at offsets ``e (E,)`` for every tile of up to ``tiles`` at once: its grid
        ``(tiles, P, E, 2)`` made whole once (``sample`` makes it per call), the divisors ``(1, P, E)``."""
        grid, divisor = self._lag_terms(-e[None, None, :, None] * self.vectors[None, :, None, :], True)
        return LagTable(grid.expand(tiles, -1, -1, -1).contiguous(), divisor)

    def sample_uniform(self, corr: torch.Tensor, table: LagTable, mode: str = "bilinear") -> torch.Tensor:
        """``sample(corr, e)`` for a table of ``uniform(e, tiles)`` (at most ``tiles`` tiles of ``corr``)."""
        return self._read(corr, table.grid[: corr.shape[0]], table.divisor, mode)

    def sample_rows(self, corr: torch.Tensor, table: LagTable, rows: torch.Tensor, mode: str = "bilinear"):
        """``sample(corr, e)`` with each tile's offsets the row ``rows (T,)`` (int) of ``table``'s ``e (K, E)``: the
        same values, with the lags' geometry looked up instead of made per tile."""
        return self._read(corr, table.grid.index_select(0, rows), table.divisor.index_select(0, rows), mode)

    def _lag_terms(self, lag: torch.Tensor, normalise: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """grid_sample's coordinates of lags ``(..., P, E, 2)`` and the divisors ``(..., P, E)`` of the samples:
        the windows' overlap there (1 without ``normalise``), NaN where the lag falls outside +-7 (one in-place
        division then divides and masks: x / 1 = x exactly)."""
        divisor = (self._overlap(lag[..., 0]) * self._overlap(lag[..., 1])).clamp(min=0.05) if normalise else \
            torch.ones_like(lag[..., 0])
        inside = (lag.abs() <= CORR_RADIUS + 1e-4).all(dim=-1)
        return lag / CORR_RADIUS, torch.where(inside, divisor, torch.full_like(divisor, float("nan")))

    @staticmethod
    def _read(corr: torch.Tensor, grid: torch.Tensor, divisor: torch.Tensor, mode: str) -> torch.Tensor:
        """``(T, P, E)`` samples of ``corr (T, P, 15, 15)`` at ``grid (T, P, E, 2)`` over ``divisor (T|1, P, E)``."""
        tiles, npairs = corr.shape[:2]
        side = 2 * CORR_RADIUS + 1
        values = F.grid_sample(corr.reshape(tiles * npairs, 1, side, side).float(),
                               grid.reshape(tiles * npairs, 1, -1, 2), mode=mode, padding_mode="zeros",
                               align_corners=True)
        return values.reshape(tiles, npairs, -1).div_(divisor)


class LagTable(NamedTuple):
    """``AxisSampler.table``: per row of offsets, grid_sample's coordinates ``(K, P, E, 2)`` and the samples'
    divisors ``(K, P, E)`` (NaN outside +-7)."""

    grid: torch.Tensor
    divisor: torch.Tensor


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


# Lags closer than this (in baselines) are one group: offsets read from rig files are rounded decimals.
LAG_TOLERANCE = 1e-6


class DirectionGroup(NamedTuple):
    """One direction group of pairs (see :func:`direction_groups`)."""

    lag: tuple  # (x, y) the group's lag per unit residual disparity, baselines (x right, y down)
    members: tuple  # ((pair index, mirrored), ...): mirrored where the pair's lag is -lag


def direction_groups(offsets, pairs) -> tuple[DirectionGroup, ...]:
    """Pairs grouped by their full lag vector ``v = r_b - r_a`` (direction and length), for the network layers.

    Convention: a pair whose lag is ``-v`` joins ``v``'s group, mirrored (its correlation is point-mirrored
    about the zero lag before it is combined: conj(A) B of the swapped pair). A group's lag is oriented with
    x > 0, or x = 0 and y > 0 (y down). Groups are ordered by lag length, then by the lag's angle
    atan2(y, x) mod 180 degrees ascending (0 = horizontal, 90 = vertical, y down). Members keep the pairs'
    order. For the quad this gives the network's [hor (1, 0), vert (0, 1), diag-main (1, 1), diag-other
    (1, -1)] with pairs [(0, 1), (2, 3)], [(0, 2), (1, 3)], [(0, 3)], [(2, 1)]; a binocular rig has one group.

    Args:
        offsets: ``(cams, 2)`` camera offsets r_i in baselines (x right, y down).
        pairs: ``(P, 2)`` camera pairs (first, second).

    Returns:
        ``G`` groups ``(lag (x, y) floats, ((pair, mirrored), ...))``.

    >>> [g.lag for g in direction_groups(tables.QUAD_OFFSETS, tables.QUAD_PAIRS)]
    [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
    """
    r = np.asarray(offsets, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"offsets: expected shape (cams, 2), got {r.shape}")
    pair_list = [tuple(p) for p in pairs]
    if not pair_list or any(len(p) != 2 or not all(0 <= c < len(r) for c in p) or p[0] == p[1] for p in pair_list):
        raise ValueError(f"pairs: expected a non-empty list of (a, b) camera indices in 0..{len(r) - 1}, a != b, "
                         f"got {pairs!r}")
    vectors = pair_vectors(r, pair_list)
    if np.any(np.hypot(vectors[:, 0], vectors[:, 1]) < LAG_TOLERANCE):
        raise ValueError(f"pairs: a pair of cameras at the same offset has no lag direction ({pairs!r})")
    groups: list[tuple[np.ndarray, list]] = []
    for index, v in enumerate(vectors):
        mirrored = v[0] < -LAG_TOLERANCE or (abs(v[0]) <= LAG_TOLERANCE and v[1] < 0)
        lag = -v if mirrored else v
        for group_lag, members in groups:
            if np.abs(group_lag - lag).max() <= LAG_TOLERANCE:
                members.append((index, bool(mirrored)))
                break
        else:
            groups.append((lag, [(index, bool(mirrored))]))

    def order(group):
        lag = group[0]
        angle = np.degrees(np.arctan2(lag[1], lag[0])) % 180.0
        return round(float(np.hypot(*lag)), 6), round(float(angle), 6) % 180.0

    return tuple(DirectionGroup(tuple(float(c) + 0.0 for c in lag), tuple(members))
                 for lag, members in sorted(groups, key=order))
