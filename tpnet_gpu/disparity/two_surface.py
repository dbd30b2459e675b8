"""Two-surface tiles: a tile whose window holds a foreground edge over the background sees both surfaces; report
both disparities and their weights (issue 17 item 4; motion_and_surfaces.md §4).

The surfaces' disparities come from the tile's measured 3x3 neighbourhood (``depth_candidates``: its second
largest and second least disparity - an edge tile's neighbours on either side see one surface each, measured
cleanly; the second of each end ignores one stray neighbour); the tile's own correlation decides whether its
window holds both. ``measure_surfaces`` correlates a candidate tile once at the middle of its two depths and, when
both fit in that correlation's view, fits two peaks of the tile's own single-surface shape to the one lobe they
make (``two_peaks.LobeFit``); a wider pair (a near board over a far background) is correlated at each depth
and both peaks must be strong (``min_strength``, the weaker at least ``min_ratio`` of the stronger).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tpnet_gpu.disparity.grid import neighbourhood
from tpnet_gpu.disparity.measure import axis_peak, row_chunks
from tpnet_gpu.disparity.two_peaks import LobeFit

SEPARATION = 1.0  # px: depths closer than this are one surface
MIN_RATIO = 0.3  # a wide pair's weaker peak's least share of the stronger one's height
MIN_STRENGTH = 0.1  # a wide pair's peaks' least height (the engine's strength scale)


@dataclass(frozen=True)
class Surfaces:
    """Two surfaces per tile, torch ``(tiles_y, tiles_x)`` each: ``foreground`` (the larger disparity) and
    ``background`` px, their ``weights`` (peak heights over their sum; w_fg + w_bg = 1); all NaN where the tile
    shows one surface only."""

    foreground: torch.Tensor
    background: torch.Tensor
    w_foreground: torch.Tensor
    w_background: torch.Tensor


def _ranked(disparity: torch.Tensor, rank: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(low, high)`` ``(ty, tx)`` each: the ``rank``-th least and largest (0: the extremes) of each tile's
    measured 3x3 neighbourhood's disparities; NaN where at most 2 ``rank`` + 1 of them are measured."""
    windows = neighbourhood(disparity)  # (ty, tx, 9)
    count = torch.isfinite(windows).sum(dim=-1)
    ordered = torch.sort(torch.nan_to_num(windows, nan=float("inf"), posinf=float("inf")), dim=-1).values
    low = ordered[..., rank]
    high = torch.gather(ordered, -1, (count - 1 - rank).clamp(min=0)[..., None])[..., 0]
    nan = torch.full_like(low, float("nan"))
    enough = count > 2 * rank + 1
    return torch.where(enough, low, nan), torch.where(enough, high, nan)


def neighbourhood_range(disparity: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(low, high)`` ``(ty, tx)`` each: the least and largest of each tile's measured 3x3 neighbourhood's
    disparities (NaN where none is measured)."""
    return _ranked(disparity, 0)


def depth_candidates(disparity: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(background, foreground)`` ``(ty, tx)`` each: the second least and second largest of each tile's measured
    3x3 neighbourhood's disparities (one stray neighbour - a flat tile's outlier - moves neither); NaN where at
    most 3 are measured."""
    return _ranked(disparity, 1)


def _passes(engine, target: torch.Tensor, active: torch.Tensor):
    """``(index, corr rows)`` chunks of one pass of ``engine``'s loaded frame at ``target (ty, tx)`` over the
    ``active (ty, tx)`` tiles."""
    corr = engine.measure_at(engine.tp, torch.nan_to_num(target, nan=0.0), active=active, layers=False).corr
    yield from row_chunks(corr, torch.nonzero(active.reshape(-1), as_tuple=True)[0])


def measure_surfaces(engine, disparity: torch.Tensor, active: torch.Tensor | None = None, *,
                     reach: float | None = None) -> Surfaces:
    """Both surfaces of the tiles of the frame loaded in ``engine`` (a ``DisparityEngine`` after ``run``), from
    its disparities ``(ty, tx)``; ``active``: the tiles to try (default: every tile whose ``depth_candidates``
    are at least ``SEPARATION`` apart); ``reach``: one correlation's view, +-px (default: the engine's, at most
    the pairs' lags less 1).

    A pair of depths at most 2 ``reach`` - 2 px apart: one pass at their middle, ``LobeFit`` with each peak
    within its radius of its depth. A wider one: a pass at each depth, its peak within 1 px of the zero offset
    (``axis_peak``). Costs 1-2 passes of the tried tiles."""
    reach = min(reach if reach is not None else engine.config.reach, engine.sampler.reach - 1.0)
    grid = disparity.shape
    low, high = depth_candidates(disparity)
    todo = torch.isfinite(low) & (high - low >= SEPARATION)
    if active is not None:
        todo = todo & active
    near = todo & (high - low <= 2 * reach - 2.0)
    wide = todo & ~near
    two = torch.zeros(disparity.numel(), dtype=torch.bool, device=disparity.device)
    w_fg = torch.full((disparity.numel(),), float("nan"), device=disparity.device)
    if bool(near.any()):
        fit = LobeFit(engine.sampler, reach=reach, min_separation=SEPARATION)
        middle = 0.5 * (low + high)
        for index, rows in _passes(engine, middle, near):
            half = 0.5 * (high - low).reshape(-1).index_select(0, index)
            two[index], w_fg[index] = fit.measure(rows, -half, half)
    if bool(wide.any()):
        heights = []
        for depth in (high, low):
            v = torch.zeros(disparity.numel(), device=disparity.device)
            for index, rows in _passes(engine, depth, wide):
                _, value, ok = axis_peak(engine.sampler, rows, torch.zeros(index.numel(), device=rows.device))
                v[index] = torch.where(ok, value, torch.zeros_like(value))
            heights.append(v)
        v_fg, v_bg = heights
        weaker, stronger = torch.minimum(v_fg, v_bg), torch.maximum(v_fg, v_bg)
        found = wide.reshape(-1) & (weaker >= MIN_STRENGTH) & (weaker >= MIN_RATIO * stronger)
        two = two | found
        w_fg = torch.where(found, v_fg / (v_fg + v_bg).clamp(min=1e-6), w_fg)
    nan = torch.full_like(w_fg, float("nan"))
    pick = lambda x: torch.where(two, x, nan).reshape(grid)  # noqa: E731
    return Surfaces(pick(high.reshape(-1)), pick(low.reshape(-1)), pick(w_fg), pick(1 - w_fg))
