"""``tpnet process`` outputs (tpnet_gpu/outputs/frame_outputs.py, docs/outputs.md) on a rendered 160x120 demo scene.

Oracles: the scene itself, ray-traced at the tile centres (``Scene.trace``: the hit's depth and 3-D point, never
through ``Rig.distance`` or ``Rig.image_to_world``); the pinhole formula Z = f B / (d p) and its projection
x = W/2 + F X / Z, y = H/2 - F Y / Z written out here from the rig's numbers; an independent little PLY reader
(NumPy) and the PNG signature / Pillow's decoder; the shipped weights as a "trained" file (same file: the same
disparities) and the binocular weights as one for another rig (refused).
"""

import shutil

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu.camera import Rig
from tpnet_gpu.cli import main
from tpnet_gpu.net import infer
from tpnet_gpu.scenes import Sensor, demo_scene, render
from tpnet_gpu.scenes.folder import save

WIDTH, HEIGHT = 160, 120
GOOD_PX = 0.1  # tiles whose disparity is within this of the ground truth count as "correct"


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """(scene, rig, scene folder, output folder of `tpnet process`)."""
    root = tmp_path_factory.mktemp("outputs")
    rig = Rig(width=WIDTH, height=HEIGHT)
    scene = demo_scene(rig, seed=0)
    save(render(scene, rig, sensor=Sensor(), supersample=1, seed=0), root / "scene", name="demo-0")
    out = root / "out"
    assert main(["process", str(root / "scene"), "--out", str(out), "--device", "cpu", "--backend", "warp"]) == 0
    return scene, rig, root / "scene", out


def _truth(scene, rig, shape):
    """Ray-traced ground truth at the tile centres: depth Z (m) ``(ty, tx)`` and hit points (m) ``(ty, tx, 3)``."""
    ty, tx = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    x, y = 8.0 * tx + 4.0, 8.0 * ty + 4.0
    p, f = rig.pixel_size_mm, rig.focal_mm
    dirs = np.stack([(x - WIDTH / 2) * p, -(y - HEIGHT / 2) * p, np.full(x.shape, -f)], -1).reshape(-1, 3)
    _, depth_mm, _ = scene.trace(np.zeros_like(dirs), dirs)
    hits = dirs * (depth_mm / f)[:, None]  # a ray (x, y, -f) reaches depth Z at Z / f times itself
    return depth_mm.reshape(shape) / 1000.0, hits.reshape(*shape, 3) / 1000.0


def _correct(disparity, gt_depth, rig):
    gt_disparity = rig.focal_mm * rig.baseline_mm / (gt_depth * 1000.0 * rig.pixel_size_mm)
    with np.errstate(invalid="ignore"):
        return np.abs(disparity - gt_disparity) < GOOD_PX, gt_disparity


def read_ply(path):
    """An independent binary little-endian PLY reader: (comments, vertex records as a NumPy structured array)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").splitlines()
    assert lines[0] == "ply" and lines[1] == "format binary_little_endian 1.0"
    kinds = {"float": "<f4", "uchar": "u1", "double": "<f8", "int": "<i4"}
    count = next(int(line.split()[2]) for line in lines if line.startswith("element vertex"))
    fields = [(line.split()[2], kinds[line.split()[1]]) for line in lines if line.startswith("property")]
    records = np.frombuffer(data[end:], dtype=fields)
    assert len(records) == count  # nothing after the vertices
    return [line[8:] for line in lines if line.startswith("comment ")], records


def test_depth_is_the_ground_truth_depth_where_the_disparity_is(processed):
    # Oracle: the scene ray-traced at the tile centres; depth error follows the disparity error dZ/Z = dd/d.
    scene, rig, _, out = processed
    disparity = tifffile.imread(out / "disparity.tif")
    depth = tifffile.imread(out / "depth.tif")
    assert depth.dtype == np.float32 and depth.shape == disparity.shape == (HEIGHT // 8, WIDTH // 8)
    gt_depth, _ = _truth(scene, rig, depth.shape)
    good, gt_disparity = _correct(disparity, gt_depth, rig)
    assert good.sum() >= 60  # enough tiles (of 300) for the check to mean something
    relative = np.abs(depth[good] - gt_depth[good]) / gt_depth[good]
    bound = np.abs(disparity[good] - gt_disparity[good]) / disparity[good]
    np.testing.assert_array_less(relative, bound * 1.001 + 1e-6)
    # everywhere: Z = f B / (d p) (rtol 1e-6: float32), NaN exactly where the disparity is
    measured = np.isfinite(disparity) & (disparity > 0)
    physics = rig.focal_mm * rig.baseline_mm / (disparity[measured].astype(np.float64) * rig.pixel_size_mm) / 1000
    np.testing.assert_allclose(depth[measured], physics, rtol=1e-6)
    np.testing.assert_array_equal(np.isnan(depth), np.isnan(disparity))


def test_points_reproject_to_their_tile_centres_at_the_right_depth(processed):
    # Oracles: the pinhole projection written out here (tile centres exact to 1e-3 px), depth.tif, the traced
    # hit points (distance error bounded by the disparity error), the texture's 8x8 cell means.
    scene, rig, _, out = processed
    disparity = tifffile.imread(out / "disparity.tif")
    depth = tifffile.imread(out / "depth.tif")
    comments, points = read_ply(out / "points.ply")
    measured = np.isfinite(disparity) & (disparity > 0)
    assert len(points) == measured.sum() > 0
    xyz = np.stack([points["x"], points["y"], points["z"]], -1).astype(np.float64)
    assert (xyz[:, 2] < 0).all()  # in front of the rig: z toward the viewer
    focal_px = rig.focal_mm / rig.pixel_size_mm
    x_px = WIDTH / 2 + focal_px * xyz[:, 0] / -xyz[:, 2]
    y_px = HEIGHT / 2 - focal_px * xyz[:, 1] / -xyz[:, 2]
    ty, tx = np.nonzero(measured)  # row-major tile order
    np.testing.assert_allclose(x_px, 8.0 * tx + 4.0, atol=1e-3)
    np.testing.assert_allclose(y_px, 8.0 * ty + 4.0, atol=1e-3)
    np.testing.assert_allclose(-xyz[:, 2], depth[measured], rtol=1e-6)
    np.testing.assert_array_equal(points["confidence"], tifffile.imread(out / "confidence.tif")[measured])
    gt_depth, hits = _truth(scene, rig, disparity.shape)
    good, gt_disparity = _correct(disparity, gt_depth, rig)
    sel = good[measured]
    miss = np.linalg.norm(xyz[sel] - hits[ty[sel], tx[sel]], axis=-1) / np.linalg.norm(hits[ty[sel], tx[sel]], axis=-1)
    bound = np.abs(disparity - gt_disparity)[ty[sel], tx[sel]] / disparity[ty[sel], tx[sel]]
    np.testing.assert_array_less(miss, bound * 1.001 + 1e-6)
    # colours: the texture's alpha-weighted mean over each tile's 8x8 cell, / white (from the header), gamma 2.2
    white = float(next(c for c in comments if c.startswith("colours:")).split("white ")[1].split(",")[0])
    texture = tifffile.imread(out / "texture.tif").astype(np.float64)
    for i in range(0, len(points), 17):
        cell = np.s_[8 * ty[i]: 8 * ty[i] + 8, 8 * tx[i]: 8 * tx[i] + 8]
        alpha = texture[3][cell]
        mean = np.array([(texture[c][cell] * alpha).sum() / alpha.sum() for c in range(3)])
        expected = np.clip(mean / white, 0, 1) ** (1 / 2.2) * 255
        np.testing.assert_allclose([points["red"][i], points["green"][i], points["blue"][i]], expected, atol=1.0)


def test_every_map_has_a_png_figure_of_the_documented_size(processed):
    # Oracle: the PNG signature, Pillow's full decode, and the figure width docs/outputs.md gives (640 px).
    _, _, _, out = processed
    for name in ("disparity", "confidence", "depth", "texture_figure"):
        path = out / f"{name}.png"
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        with Image.open(path) as image:
            image.load()
            assert image.size[0] == 640 and 400 < image.size[1] < 700, (name, image.size)
    assert (out / "texture.png").exists() and (out / "texture.tif").exists()


def test_weights_a_trained_file_and_one_for_another_rig(processed, tmp_path, capsys):
    # Oracle: a copy of the shipped quad weights is the same network (bitwise the same disparity); the binocular
    # weights have other layer lags (refused, one line, exit 2); a missing file is named.
    _, _, folder, out = processed
    mine = tmp_path / "mine.pt"
    shutil.copy(infer.DEFAULT_WEIGHTS, mine)
    shutil.copy(infer.DEFAULT_WEIGHTS.with_suffix(".json"), mine.with_suffix(".json"))
    assert main(["process", str(folder), "--out", str(tmp_path / "a"), "--device", "cpu", "--backend", "warp",
                 "--weights", str(mine), "--no-figures"]) == 0
    assert "weights mine.pt" in capsys.readouterr().out
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "a" / "disparity.tif"),
                                  tifffile.imread(out / "disparity.tif"))
    assert not (tmp_path / "a" / "disparity.png").exists()  # --no-figures
    binocular = infer.WEIGHTS_DIR / "tpnet_binocular_v1.pt"
    assert main(["process", str(folder), "--out", str(tmp_path / "b"), "--weights", str(binocular)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tpnet process: error: weights:") and "lags" in err and "\n" not in err
    assert not (tmp_path / "b").exists()
    assert main(["process", str(folder), "--out", str(tmp_path / "c"), "--weights", str(tmp_path / "no.pt")]) == 2
    assert "weights: weights file (from `tpnet train`) not found" in capsys.readouterr().err


def test_verbose_logs_and_no_progress_bar_off_a_terminal(processed, tmp_path, capsys):
    # Oracle: the logging records of the library (INFO with -v, none without); capsys' stderr is no terminal,
    # so no bar's carriage returns.
    _, _, folder, _ = processed
    argv = ["process", str(folder), "--device", "cpu", "--backend", "warp", "--no-figures"]
    assert main([*argv, "--out", str(tmp_path / "quiet")]) == 0
    quiet = capsys.readouterr().err
    assert "INFO" not in quiet and "\r" not in quiet
    assert main(["-v", *argv, "--out", str(tmp_path / "loud")]) == 0
    loud = capsys.readouterr().err
    assert "INFO tpnet_gpu.pipeline: pipeline 160x120" in loud and "INFO tpnet_gpu.cli: frame" in loud
    assert "DEBUG" not in loud and "\r" not in loud
    assert main(["-vv", *argv, "--out", str(tmp_path / "louder")]) == 0
    assert "DEBUG tpnet_gpu.outputs.frame_outputs: wrote" in capsys.readouterr().err
