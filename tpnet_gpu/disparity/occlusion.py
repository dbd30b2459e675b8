"""Which cameras a nearer surface hides a tile from, and the pairs that still see it (disparity.md §4, step 5).

Convention (pairs.py): camera i sees a centre-camera point p of disparity d at p - d r_i (r_i its offset in
baselines). A tile at p tried at a background disparity b is hidden from camera i by a tile u of the current
map with disparity D_u > b when u's image in that camera, p_u - D_u r_i, falls on the tile's window there,
p - b r_i: when ``|8 (u - t) - r_i (D_u - b)| <= OCCLUDER_REACH`` in x and y (tile units of 8 px). Torch on the
map's device, vectorised over the tiles asked about.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu.layout import HALF_TILE, TILE_STRIDE

# A nearer tile hides the window when its centre lands within half a window of the window's centre.
OCCLUDER_REACH = HALF_TILE


def lowest(disparity: torch.Tensor, radius: int) -> torch.Tensor:
    """``(ty, tx)``: the least finite disparity of each tile's ``(2 radius + 1)^2`` neighbourhood (inf if none)."""
    high = torch.where(torch.isnan(disparity), -float("inf"), -disparity)  # (nan_to_num would give the float max)
    return -F.max_pool2d(high[None, None], 2 * radius + 1, stride=1, padding=radius)[0, 0]


class Occlusion:
    """Occlusion of tiles by nearer tiles of a disparity map, for a rig's camera ``offsets (cams, 2)`` and
    ``pairs (P, 2)``, nearer meaning more than ``jump`` px nearer, over disparity differences up to ``span`` px;
    the pair table lives on ``device`` (the maps' device: no copy per frame).

    The tile offsets a camera can be hidden from are fixed by the rig: they lie along -r_i (a nearer surface
    shows displaced by -D r_i), so each camera keeps only those (host work once, here)."""

    def __init__(self, offsets, pairs, jump: float, span: float, device=None):
        r = np.asarray(offsets, dtype=np.float64)
        self.jump = float(jump)
        self.pairs = torch.as_tensor(np.asarray(pairs, dtype=np.int64), device=device)
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

    def hidden(self, disparity: torch.Tensor, background: torch.Tensor, tiles: torch.Tensor) -> torch.Tensor:
        """``(N, cams)`` bool: camera i's view of tile ``tiles (N,)`` (flat numbers) at disparity ``background
        (N,)`` is covered by a tile of ``disparity (ty, tx)`` more than ``jump`` px nearer (see the module
        docstring). Only those tiles are read (a few gathers per camera and tile offset)."""
        width = disparity.shape[1] + 2 * self.radius
        grid = F.pad(disparity[None, None], (self.radius,) * 4, value=float("nan")).reshape(-1)  # NaN: never nearer
        base = (tiles // disparity.shape[1] + self.radius) * width + tiles % disparity.shape[1] + self.radius
        out = torch.zeros((tiles.numel(), len(self.offsets)), dtype=torch.bool, device=disparity.device)
        for cam, ((rx, ry), reach) in enumerate(zip(self.offsets, self.reach)):
            for dy, dx in reach:
                rel = grid[base + dy * width + dx] - background
                out[:, cam] |= ((rel > self.jump) & ((TILE_STRIDE * dx - rx * rel).abs() <= OCCLUDER_REACH)
                                & ((TILE_STRIDE * dy - ry * rel).abs() <= OCCLUDER_REACH))
        return out

    def visible_pairs(self, hidden: torch.Tensor) -> torch.Tensor:
        """``(N, P)`` bool: pairs neither of whose cameras is ``hidden (N, cams)``."""
        return ~(hidden[..., self.pairs[:, 0]] | hidden[..., self.pairs[:, 1]])
