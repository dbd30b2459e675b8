"""The tile checks (``tpnet_gpu/disparity/checks.py``). Oracle: the ideal rig's geometry by hand - camera j sees
the tile centred at c with disparity d at c - d * offsets[j] - and maps whose cross-check differences are known."""

from __future__ import annotations

import torch

from tpnet_gpu.disparity.checks import cross_camera, cross_difference, windows_inside

PAIR = torch.tensor([[0.0, 0.0], [1.0, 0.0]])  # a stereo pair seen from the left camera


def test_windows_leave_the_right_image_left_of_the_disparity():
    d = torch.full((4, 10), 20.0)
    inside = windows_inside(d, PAIR, (32, 80))
    # the right camera sees tile tx at 8 tx + 4 - 20, which must be >= 4: tx >= 2.5
    assert inside[:, 3:].all() and not inside[:, :3].any()
    d[0, 5] = float("nan")
    assert not windows_inside(d, PAIR, (32, 80))[0, 5]


def test_cross_difference():
    d = torch.full((3, 12), 8.0)
    assert torch.equal(cross_difference(d, d, (1.0, 0.0))[:, 1:], torch.zeros(3, 11))
    other = d.clone()
    other[:, :] = 11.0
    assert torch.allclose(cross_difference(d, other, (1.0, 0.0))[:, 2:], torch.full((3, 10), 3.0))
    # the other camera's tile of tile 5 is at column 5 - 1 = 4 (8 px = one tile): only that one has no answer
    other = d.clone()
    other[:, 4] = float("nan")
    diff = cross_difference(d, other, (1.0, 0.0))
    assert torch.isinf(diff[:, 5]).all() and (diff[:, 6:] == 0).all()
    # left of the grid: no tile to check against
    assert torch.isinf(cross_difference(torch.full((3, 12), 30.0), other, (1.0, 0.0))[:, 0]).all()


def test_cross_camera_is_the_farthest():
    assert cross_camera(PAIR) == 1
    assert cross_camera(torch.tensor([[-0.5, 0.0], [0.5, 0.0]])) == 1
