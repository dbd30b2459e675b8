"""A rig's cameras aligned for the combined flow (motion_and_surfaces.md §1): each camera's tiles centred where
the disparity engine says the virtual camera's tile sees, at both times.

A tile (tx, ty) of the virtual camera sees a scene point at disparity d (the engine's map of frame t). Camera k
sees it at ``Rig.port_coordinates(grid, d)``; at frame t+1 the point is at grid + flow in the virtual camera,
so camera k's tile of frame t+1 is centred at ``port_coordinates(grid + flow, d + change)``, the change of
disparity being frame t+1's map there minus frame t's, as the median over each tile's 3x3 neighbourhood (the
difference of two maps carries both maps' noise). Every pair (frame t of camera k, frame t+1 of camera k) then
peaks at the same residual of the virtual camera's flow, so the pairs combine. Without the alignment each
camera's tile sits on its own image grid, and near a depth edge the cameras' tiles see different objects; a
motion in depth (a forward translation) moves each camera's view by another amount. The rig's model is NumPy:
a host round trip per pass, as the engine's for a calibrated rig.
"""

from __future__ import annotations

import numpy as np
import torch

from tpnet_gpu.camera import Rig, grid_centres
from tpnet_gpu.disparity.grid import neighbourhood
from tpnet_gpu.layout import TILE_CENTRE, TILE_STRIDE

FILL_STEPS = 8  # neighbour-median sweeps that carry measured disparities into unmeasured tiles


def filled(disparity: torch.Tensor) -> torch.Tensor:
    """``(ty, tx)`` disparity with unmeasured (NaN) tiles set to their measured neighbours' median, repeated
    ``FILL_STEPS`` times, and what is left to the map's median (0 for a map without any): a textureless tile
    of frame t takes its surroundings' depth, which is where its flow is found if it has one."""
    d = disparity.clone()
    for _ in range(FILL_STEPS):
        missing = ~torch.isfinite(d)
        if not bool(missing.any()):
            return d
        median = torch.nanmedian(neighbourhood(d), dim=-1).values
        d = torch.where(missing, median, d)
    rest = torch.nanmedian(d) if bool(torch.isfinite(d).any()) else torch.zeros((), device=d.device)
    return torch.where(torch.isfinite(d), d, rest)


class Alignment:
    """Tile centres ``(T, 2 cams, 2)`` of a rig's frames t and t+1 for a flow (module docstring).

    Args:
        rig: the rig (its ``cams`` cameras, its frame size).
        grid: (tiles_y, tiles_x) of the virtual camera.
        device: where the centres are made.
    """

    def __init__(self, rig: Rig, grid: tuple[int, int], device):
        self.rig, self.grid, self.device = rig, grid, device
        self.tiles = grid_centres(*grid).reshape(-1, 2)  # (T, 2) virtual grid
        self.d_t = self.d_t1 = self.first = None

    def set_maps(self, d_t: torch.Tensor, d_t1: torch.Tensor) -> None:
        """The disparity maps ``(tiles_y, tiles_x)`` of frames t and t+1 (NaN: unmeasured, filled here)."""
        self.d_t = filled(d_t).reshape(-1).double().cpu().numpy()
        self.d_t1 = filled(d_t1).double().cpu().numpy()
        self.first = self.rig.port_coordinates(self.tiles, self.d_t)  # (T, cams, 2) frame t's centres

    def centres(self, flow: torch.Tensor) -> torch.Tensor:
        """``(T, 2 cams, 2)`` float32: cameras' tile centres at frame t, then at frame t+1 for ``flow (T, 2)``
        (NaN rows: the frame t positions)."""
        f = np.nan_to_num(flow.double().cpu().numpy(), nan=0.0)
        moved = self.tiles + f
        # frame t+1's disparity at the moved point: its nearest tile's (a depth edge keeps one side's)
        iy = np.clip(np.rint((moved[:, 1] - TILE_CENTRE) / TILE_STRIDE), 0, self.grid[0] - 1).astype(int)
        ix = np.clip(np.rint((moved[:, 0] - TILE_CENTRE) / TILE_STRIDE), 0, self.grid[1] - 1).astype(int)
        # the motion in depth, the disparity change, as the 3x3 median over the tiles: the difference of two
        # maps carries both maps' noise (3 tuning scenes, 4 cameras, the translations: mean gross 2.2 -> 1.7 %)
        change = torch.from_numpy(self.d_t1[iy, ix] - self.d_t).reshape(self.grid)
        change = torch.nanmedian(neighbourhood(change), dim=-1).values.reshape(-1).numpy()
        second = self.rig.port_coordinates(moved, self.d_t + change)
        return torch.from_numpy(np.concatenate([self.first, second], axis=1).astype(np.float32)).to(self.device)
