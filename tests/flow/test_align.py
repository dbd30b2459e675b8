"""Aligning a rig's cameras for the combined flow (tpnet_gpu/flow/align.py). Oracles: the ideal rig's geometry by
hand (camera k sees the virtual camera's point c at disparity d at c - d r_k, camera.md / Rig.port_coordinates),
and hand-made disparity maps."""

import numpy as np
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.flow.align import Alignment, filled


def test_filled_takes_the_neighbours_median_then_the_map_median():
    d = torch.full((4, 5), float("nan"))
    d[0, 0], d[0, 1], d[1, 0] = 2.0, 4.0, 9.0
    out = filled(d).numpy()
    assert out[0, 0] == 2.0 and out[0, 1] == 4.0 and out[1, 0] == 9.0  # measured tiles kept
    assert out[1, 1] == 4.0  # its measured neighbours 2, 4, 9: median 4
    assert np.isfinite(out).all()
    assert (filled(torch.full((2, 3), float("nan"))).numpy() == 0).all()  # nothing measured: 0 (infinity)


def test_centres_follow_the_ideal_rig_geometry():
    rig = Rig(width=64, height=48)
    grid = (6, 8)
    align = Alignment(rig, grid, "cpu")
    d_t = torch.full(grid, 3.0)
    d_t1 = torch.full(grid, 5.0)  # the scene came closer: disparity +2 everywhere
    d_t[2, 3] = float("nan")  # filled from its neighbours (3)
    align.set_maps(d_t, d_t1)
    flow = torch.tensor([1.5, -0.5]).expand(grid[0] * grid[1], 2)
    centres = align.centres(flow).numpy().reshape(*grid, 2 * rig.cams, 2)
    r = rig.offsets_array()  # (cams, 2)
    ty, tx = np.meshgrid(np.arange(grid[0]), np.arange(grid[1]), indexing="ij")
    c = np.stack([8.0 * tx + 4, 8.0 * ty + 4], axis=-1)[..., None, :]  # (ty, tx, 1, 2)
    np.testing.assert_allclose(centres[:, :, : rig.cams], c - 3.0 * r, atol=1e-4)
    np.testing.assert_allclose(centres[:, :, rig.cams :], c + np.array([1.5, -0.5]) - 5.0 * r, atol=1e-4)
