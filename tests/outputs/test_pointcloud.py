"""Depth, tile colours and the PLY writer (tpnet_gpu/outputs/pointcloud.py). Oracles: Z = f B / (d p) written out with
the quad's numbers (4.5 mm, 258 mm, 2.2 um); hand-made textures of known colours; the PLY layout read back with
NumPy. (The outputs of a rendered scene against its ray-traced ground truth: tests/outputs/test_frame_outputs.py.)"""

import numpy as np
import pytest

from tpnet_gpu.outputs import pointcloud
from tpnet_gpu.camera import Rig


def test_depth_nan_where_unmeasured_and_inf_at_or_beyond_infinity():
    d = np.array([[np.nan, 0.0, -1.5], [2.0, 10.0, 0.25]])
    z = pointcloud.depth(d, Rig())
    assert z.dtype == np.float32
    assert np.isnan(z[0, 0]) and z[0, 1] == np.inf and z[0, 2] == np.inf
    np.testing.assert_allclose(z[1], 4.5 * 258.0 / (d[1] * 0.0022) / 1000.0, rtol=1e-6)
    with pytest.raises(ValueError, match=r"disparity: expected a map \(rows, columns\) of tiles or pixels, got shape \(3,\)"):
        pointcloud.depth(np.ones(3), Rig())


def test_tile_colours_are_alpha_weighted_cell_means():
    texture = np.zeros((4, 16, 12))  # 2x2 tiles, the right ones 4 px wide (a side that is not a multiple of 8)
    texture[0], texture[3] = 0.25, 1.0  # red at a quarter of white...
    texture[1, :8, :8] = 1.0  # ...tile (0, 0) green at white
    texture[3, 8:, 8:] = 0.0
    texture[2, 8:, 8:] = 1.0  # blue only where alpha is 0: not seen
    colours = pointcloud.tile_colours(texture, white=1.0)
    quarter = round(0.25 ** (1 / 2.2) * 255)
    assert colours.shape == (2, 2, 3) and colours.dtype == np.uint8
    np.testing.assert_array_equal(colours[0, 0], [quarter, 255, 0])
    np.testing.assert_array_equal(colours[0, 1], [quarter, 0, 0])
    np.testing.assert_array_equal(colours[1, 1], [0, 0, 0])  # no alpha: nothing to average
    grey = pointcloud.tile_colours(np.stack([np.full((8, 8), 0.25), np.ones((8, 8))]), white=1.0)
    np.testing.assert_array_equal(grey[0, 0], [quarter] * 3)  # Y, alpha: grey
    with pytest.raises(ValueError, match="texture: expected"):
        pointcloud.tile_colours(np.zeros((3, 8, 8)), white=1.0)


def test_ply_layout_and_bad_input(tmp_path):
    points = np.array([[1.0, -2.0, -30.0], [0.5, 0.25, -7.0]])
    colours = np.array([[255, 0, 10], [1, 2, 3]], dtype=np.uint8)
    path = pointcloud.write_ply(tmp_path / "p.ply", points, colours, scalars={"confidence": [0.5, 0.0]},
                                comments=("hello",))
    data = path.read_bytes()
    head, body = data.split(b"end_header\n")
    assert head.decode().splitlines() == [
        "ply", "format binary_little_endian 1.0", "comment hello", "element vertex 2", "property float x",
        "property float y", "property float z", "property uchar red", "property uchar green", "property uchar blue",
        "property float confidence"]
    assert len(body) == 2 * (4 * 4 + 3)
    first = np.frombuffer(body[:12], "<f4")
    np.testing.assert_array_equal(first, [1.0, -2.0, -30.0])
    assert body[12:15] == bytes([255, 0, 10])
    with pytest.raises(ValueError, match=r"points: expected shape \(n, 3\)"):
        pointcloud.write_ply(tmp_path / "q.ply", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="colours: expected uint8"):
        pointcloud.write_ply(tmp_path / "q.ply", points, colours.astype(np.int32))
