"""Two-surface tiles: a foreground edge over the background gives a tile's correlation two peaks along the pairs'
disparity axis; a two-peak fit reports both disparities and their weights (issue 17 item 4; motion_and_surfaces.md §4).

Per tile (``TwoSurfaceFit.measure``): the pairs' combined correlation (``combine_pairs`` of ``AxisSampler``
samples, as the engine reads it) at offsets every ``STEP`` px within +-``reach`` of the tile's target; its two
strongest local maxima at least ``separation`` px apart, the weaker at least ``min_ratio`` of the stronger; each
fitted as the engine's single peak (``measure.axis_peak``: bicubic quarter-pixel samples and a parabola).
``measure_surfaces`` picks the tiles whose measured 3x3 neighbourhood spans two depths (an edge tile's neighbours
see both sides), reads both surfaces in one correlation at the span's middle when they fit in the reach, or in two
at its ends when they do not, then iterates like the engine's refinement: each surface is re-correlated at its own
disparity (its peak is then centred, where the windows' overlap no longer skews it) and re-fitted near the zero
offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tpnet_gpu.disparity.engine import neighbourhood
from tpnet_gpu.disparity.measure import axis_peak, row_chunks
from tpnet_gpu.disparity.pairs import AxisSampler, combine_pairs

STEP = 0.5  # px between the offsets the local maxima are found at
SEPARATION = 1.0  # px: closer maxima are one surface
MIN_RATIO = 0.3  # the second maximum's least share of the first's height
REFINE_PASSES = 2


@dataclass(frozen=True)
class Surfaces:
    """Two surfaces per tile, torch ``(tiles_y, tiles_x)`` each (or ``(T,)`` from ``TwoSurfaceFit.measure``):
    ``foreground`` (the larger disparity) and ``background`` px, their ``weights`` (peak heights over their sum;
    w_fg + w_bg = 1); all NaN where the tile shows one surface only."""

    foreground: torch.Tensor
    background: torch.Tensor
    w_foreground: torch.Tensor
    w_background: torch.Tensor


class TwoSurfaceFit:
    """``measure(corr (T, P, 15, 15)) -> Surfaces`` of offsets (px) from the tiles' targets (module docstring)."""

    def __init__(self, sampler: AxisSampler, *, reach: float = 6.0, separation: float = SEPARATION,
                 min_ratio: float = MIN_RATIO, min_strength: float = 0.1):
        for name, value in (("reach", reach), ("separation", separation)):
            if not value > 0:
                raise ValueError(f"{name}: expected a number of pixels > 0, got {value!r}")
        if not 0 < min_ratio <= 1:
            raise ValueError(f"min_ratio: expected a share in (0, 1], got {min_ratio!r}")
        self.sampler = sampler
        self.separation, self.min_ratio, self.min_strength = separation, min_ratio, min_strength
        reach = min(reach, sampler.reach - 1.0)  # the +-1 px fit stays inside the lags
        self.reach = reach
        self.offsets = torch.arange(-reach, reach + 1e-6, STEP, device=sampler.vectors.device)

    def _combined(self, corr: torch.Tensor) -> torch.Tensor:
        """``(T, E)`` the pairs' combined correlation at ``self.offsets``."""
        return torch.nan_to_num(combine_pairs(self.sampler.sample(corr, self.offsets, "bicubic")), nan=-1.0)

    def strongest(self, corr: torch.Tensor):
        """``(e, value, ok)`` ``(T,)`` each: the combined correlation's strongest peak within the reach, fitted."""
        return axis_peak(self.sampler, corr, self.offsets[torch.argmax(self._combined(corr), dim=1)])

    def measure(self, corr: torch.Tensor) -> Surfaces:
        values = self._combined(corr)
        inner = torch.zeros_like(values, dtype=torch.bool)
        inner[:, 1:-1] = (values[:, 1:-1] > values[:, :-2]) & (values[:, 1:-1] >= values[:, 2:])
        low = torch.full_like(values, -float("inf"))
        first = torch.argmax(torch.where(inner, values, low), dim=1)
        apart = (self.offsets[None, :] - self.offsets[first][:, None]).abs() >= self.separation
        second = torch.argmax(torch.where(inner & apart, values, low), dim=1)
        h1 = values.gather(1, first[:, None])[:, 0]
        h2 = torch.where((inner & apart).any(dim=1), values.gather(1, second[:, None])[:, 0], low[:, 0])
        two = (h1 >= self.min_strength) & (h2 >= self.min_ratio * h1)
        e1, v1, ok1 = axis_peak(self.sampler, corr, self.offsets[first])
        e2, v2, ok2 = axis_peak(self.sampler, corr, self.offsets[second])
        two = two & ok1 & ok2 & ((e1 - e2).abs() >= self.separation)
        fg_first = e1 >= e2
        nan = torch.full_like(e1, float("nan"))
        pick = lambda a, b: torch.where(two, torch.where(fg_first, a, b), nan)  # noqa: E731
        total = (v1 + v2).clamp(min=1e-6)
        return Surfaces(pick(e1, e2), pick(e2, e1), pick(v1 / total, v2 / total), pick(v2 / total, v1 / total))


def neighbourhood_range(disparity: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(low, high)`` ``(ty, tx)`` each: the least and largest of each tile's measured 3x3 neighbourhood's
    disparities (NaN where none is measured)."""
    windows = neighbourhood(disparity)
    finite = torch.isfinite(windows)
    nan = torch.full(disparity.shape, float("nan"), device=disparity.device)
    high = torch.where(finite, windows, torch.full_like(windows, -float("inf"))).amax(dim=-1)
    low = torch.where(finite, windows, torch.full_like(windows, float("inf"))).amin(dim=-1)
    some = finite.any(dim=-1)
    return torch.where(some, low, nan), torch.where(some, high, nan)


def _passes(engine, target: torch.Tensor, active: torch.Tensor):
    """``(index, corr rows)`` chunks of one pass of ``engine``'s loaded frame at ``target (ty, tx)`` over the
    ``active (ty, tx)`` tiles."""
    corr = engine.measure_at(engine.tp, torch.nan_to_num(target, nan=0.0), active=active).corr
    yield from row_chunks(corr, torch.nonzero(active.reshape(-1), as_tuple=True)[0])


def measure_surfaces(engine, disparity: torch.Tensor, active: torch.Tensor | None = None,
                     fit: TwoSurfaceFit | None = None) -> Surfaces:
    """Both surfaces of the tiles of the frame loaded in ``engine`` (a ``DisparityEngine`` after ``run``), from
    its disparities ``(ty, tx)``; ``active``: the tiles to try (default: every tile whose measured 3x3
    neighbourhood spans at least the fit's separation).

    A tile whose neighbourhood spans at most 2 ``reach`` - 2 px is correlated once at the span's middle and fitted
    with two peaks (``TwoSurfaceFit.measure``); a wider one (a near board over a far background) twice, at the
    span's ends, each pass's strongest peak one surface (kept as two when both are strong enough, the weaker at
    least ``min_ratio`` of the stronger). Then each surface is re-correlated at its own disparity and re-fitted
    near the zero offset, ``REFINE_PASSES`` times. Costs 1-2 passes of the tried tiles and at most
    ``2 REFINE_PASSES`` of the two-surface ones."""
    fit = fit or TwoSurfaceFit(engine.sampler, reach=engine.config.reach)
    grid = disparity.shape
    low, high = neighbourhood_range(disparity)
    todo = torch.isfinite(low) & (high - low >= fit.separation)
    if active is not None:
        todo = todo & active
    near = todo & (high - low <= 2 * fit.reach - 2.0)
    far = todo & ~near
    nan = torch.full((disparity.numel(),), float("nan"), device=disparity.device)
    fg, bg, w_fg, w_bg = (nan.clone() for _ in range(4))
    if bool(near.any()):
        middle = 0.5 * (low + high)
        for index, rows in _passes(engine, middle, near):
            found = fit.measure(rows)
            base = middle.reshape(-1).index_select(0, index)
            fg[index], bg[index] = base + found.foreground, base + found.background
            w_fg[index], w_bg[index] = found.w_foreground, found.w_background
    if bool(far.any()):
        ends = []
        for end in (high, low):
            d, v = nan.clone(), torch.zeros_like(nan)
            for index, rows in _passes(engine, end, far):
                e, value, ok = fit.strongest(rows)
                d[index] = end.reshape(-1).index_select(0, index) + e
                v[index] = torch.where(ok, value, torch.zeros_like(value))
            ends.append((d, v))
        (d_hi, v_hi), (d_lo, v_lo) = ends
        two = (far.reshape(-1) & (torch.minimum(v_hi, v_lo) >= fit.min_strength)
               & (torch.minimum(v_hi, v_lo) >= fit.min_ratio * torch.maximum(v_hi, v_lo))
               & ((d_hi - d_lo).abs() >= fit.separation))
        total = (v_hi + v_lo).clamp(min=1e-6)
        fg, bg = torch.where(two, d_hi, fg), torch.where(two, d_lo, bg)
        w_fg, w_bg = torch.where(two, v_hi / total, w_fg), torch.where(two, v_lo / total, w_bg)
    two = torch.isfinite(fg) & torch.isfinite(bg)
    for surface in (fg, bg):  # each re-correlated at its own disparity: its peak is then near the centre
        for _ in range(REFINE_PASSES):
            if not bool(two.any()):
                break
            for index, rows in _passes(engine, surface.reshape(grid), two.reshape(grid)):
                e, _, ok = axis_peak(fit.sampler, rows, torch.zeros(index.numel(), device=rows.device))
                surface[index] = surface.index_select(0, index) + torch.where(ok, e, torch.zeros_like(e))
    swapped = fg < bg  # a refined pair may cross
    out = (torch.where(swapped, bg, fg), torch.where(swapped, fg, bg), torch.where(swapped, w_bg, w_fg),
           torch.where(swapped, w_fg, w_bg))
    return Surfaces(*(o.reshape(grid) for o in out))
