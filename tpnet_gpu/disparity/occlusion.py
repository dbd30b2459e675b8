"""Which cameras a nearer surface hides a tile from, and the pairs that still see it (disparity.md §4, step 5).

Convention (pairs.py): camera i sees a centre-camera point p of disparity d at p - d r_i (r_i its offset in
baselines). A tile at p tried at a background disparity b is hidden from camera i by a tile u of the current
map with disparity D_u > b when u's image in that camera, p_u - D_u r_i, falls on the tile's window there,
p - b r_i: when ``|8 (u - t) - r_i (D_u - b)| <= OCCLUDER_REACH`` in x and y (tile units of 8 px). Torch on the
map's device, vectorised over tiles.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu.layout import TILE_SIZE

TILE_STRIDE = TILE_SIZE // 2  # px between tile centres
# A nearer tile hides the window when its centre lands within half a window of the window's centre.
OCCLUDER_REACH = TILE_SIZE / 2


def shifted(grid: torch.Tensor, dy: int, dx: int, radius: int) -> torch.Tensor:
    """``(ty, tx)``: ``grid`` at tile (y + dy, x + dx) for each tile (NaN beyond the edge); ``radius`` >= |dy|,
    |dx| is the padding of one shared padded copy (see ``padded``)."""
    ty, tx = grid.shape[0] - 2 * radius, grid.shape[1] - 2 * radius
    return grid[radius + dy: radius + dy + ty, radius + dx: radius + dx + tx]


def padded(grid: torch.Tensor, radius: int) -> torch.Tensor:
    """``(ty + 2 radius, tx + 2 radius)``: ``grid (ty, tx)`` with a NaN border (for ``shifted``)."""
    return F.pad(grid[None, None], (radius,) * 4, value=float("nan"))[0, 0]


def lowest(disparity: torch.Tensor, radius: int) -> torch.Tensor:
    """``(ty, tx)``: the least finite disparity of each tile's ``(2 radius + 1)^2`` neighbourhood (inf if none)."""
    grid = padded(disparity, radius)
    grid = torch.where(torch.isnan(grid), float("inf"), grid)  # (nan_to_num would turn inf into the float max)
    out = torch.full_like(disparity, float("inf"))
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            out = torch.minimum(out, shifted(grid, dy, dx, radius))
    return out


class Occlusion:
    """Occlusion of tiles by nearer tiles of a disparity map, for a rig's camera ``offsets (cams, 2)`` and
    ``pairs (P, 2)``, nearer meaning more than ``jump`` px nearer, over disparity differences up to ``span`` px.

    The tile offsets a camera can be hidden from are fixed by the rig: they lie along -r_i (a nearer surface
    shows displaced by -D r_i), so each camera keeps only those (host work once, here)."""

    def __init__(self, offsets, pairs, jump: float, span: float):
        r = np.asarray(offsets, dtype=np.float64)
        self.jump = float(jump)
        self.pairs = torch.as_tensor(np.asarray(pairs, dtype=np.int64))
        self.radius = int(np.ceil(np.abs(r).max() * max(span, 0.0) / TILE_STRIDE)) + 1
        rel = np.linspace(self.jump, max(span, self.jump), 64)
        self.reach: list[list[tuple[int, int]]] = []  # per camera: (dy, dx) tile offsets an occluder can sit at
        for rx, ry in r:
            offsets_c = []
            for dy in range(-self.radius, self.radius + 1):
                for dx in range(-self.radius, self.radius + 1):
                    if np.any((np.abs(TILE_STRIDE * dx - rx * rel) <= OCCLUDER_REACH)
                              & (np.abs(TILE_STRIDE * dy - ry * rel) <= OCCLUDER_REACH)):
                        offsets_c.append((dy, dx))
            self.reach.append(offsets_c)
        self.offsets = [(float(rx), float(ry)) for rx, ry in r]

    def hidden(self, disparity: torch.Tensor, background: torch.Tensor) -> torch.Tensor:
        """``(ty, tx, cams)`` bool: camera i's view of each tile at disparity ``background (ty, tx)`` is covered by
        a tile of ``disparity (ty, tx)`` more than ``jump`` px nearer (see the module docstring)."""
        grid = padded(disparity, self.radius)
        out = torch.zeros((*disparity.shape, len(self.offsets)), dtype=torch.bool, device=disparity.device)
        for cam, ((rx, ry), reach) in enumerate(zip(self.offsets, self.reach)):
            for dy, dx in reach:
                rel = shifted(grid, dy, dx, self.radius) - background  # NaN beyond the edge: never nearer
                out[..., cam] |= ((rel > self.jump) & ((TILE_STRIDE * dx - rx * rel).abs() <= OCCLUDER_REACH)
                                  & ((TILE_STRIDE * dy - ry * rel).abs() <= OCCLUDER_REACH))
        return out

    def visible_pairs(self, hidden: torch.Tensor) -> torch.Tensor:
        """``(ty, tx, P)`` bool: pairs neither of whose cameras is ``hidden (ty, tx, cams)``."""
        pairs = self.pairs.to(hidden.device)
        return ~(hidden[..., pairs[:, 0]] | hidden[..., pairs[:, 1]])
