"""Where the flow iteration starts (motion_and_surfaces.md §1): the flow of 2x2-binned frames, scaled up to the
full-resolution tile grid.

Near objects under a translation move tens of px against a far background, beyond one correlation's reach
(6 px) from a start at 0: the binned frames halve every flow (and the next level halves it again), so the
coarse level's flow, doubled, starts each full-resolution tile in the right basin. Binning a Bayer mosaic's 2x2
quads gives one mono pixel per quad, so the coarse levels need no CFA.
"""

from __future__ import annotations

import torch

from tpnet_gpu.layout import TILE_CENTRE, TILE_SIZE, TILE_STRIDE

BIN = 2  # px of a level per px of the next coarser one


def coarse_size(height: int, width: int) -> tuple[int, int] | None:
    """The next coarser level's frame size (binned by ``BIN``, cropped to whole 8-px tiles), or None where it
    would hold less than one tile processor window (``TILE_SIZE``) in either direction."""
    h, w = height // BIN // 8 * 8, width // BIN // 8 * 8
    return (h, w) if min(h, w) >= TILE_SIZE else None


def bin_frames(frames: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """``frames (cams, H, W)`` -> ``(cams, h, w)`` the means of 2x2 blocks, cropped to ``size`` (h, w)."""
    cams = frames.shape[0]
    h, w = size
    top = frames[:, : BIN * h, : BIN * w].float()
    return top.reshape(cams, h, BIN, w, BIN).mean(dim=(2, 4))


def scaled_start(coarse: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """Start ``(tiles_y * tiles_x, 2)`` of a ``grid`` (tiles_y, tiles_x) from the next coarser level's flow
    ``coarse (cty, ctx, 2)``: ``BIN`` times the flow of the coarse tile nearest each tile centre (the nearest,
    not an interpolation: a tile at a depth edge takes one side's flow; NaN where that tile has none or the
    centre is outside the coarse grid)."""
    cty, ctx = coarse.shape[:2]
    device = coarse.device
    # fine centre 8 t + 4 is at (8 t + 4) / BIN on the coarse level, whose tile c is centred at 8 c + 4
    iy, ix = (torch.round(((TILE_STRIDE * torch.arange(n, device=device) + TILE_CENTRE) / BIN - TILE_CENTRE)
                          / TILE_STRIDE).long() for n in grid)
    inside = (iy[:, None] >= 0) & (iy[:, None] < cty) & (ix[None, :] >= 0) & (ix[None, :] < ctx)
    start = BIN * coarse[iy.clamp(0, cty - 1)][:, ix.clamp(0, ctx - 1)]  # (ty, tx, 2)
    start = torch.where(inside[..., None], start, torch.full_like(start, float("nan")))
    return start.reshape(-1, 2)
