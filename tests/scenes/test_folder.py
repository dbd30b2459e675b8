"""Scene folders: render -> DNGs + ground truth + scene.json -> read back through rawpy. Oracle: the rendered
arrays themselves (bit-exact raws, equal ground truth, the same rig)."""

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.cli import main
from tpnet_gpu.scenes import demo_scene, render
from tpnet_gpu.scenes.folder import load, save


def test_scene_folder_round_trip(tmp_path):
    rig = Rig(width=96, height=64)
    rendered = render(demo_scene(rig), rig, supersample=1)
    folder = save(rendered, tmp_path / "scene", name="demo-0")
    loaded = load(folder)
    assert loaded.rig == rig and loaded.cfa == rendered.sensor.cfa
    np.testing.assert_array_equal(loaded.frames, rendered.raws.astype(np.float32) - rendered.sensor.black_level)
    for key, value in rendered.ground_truth().items():
        np.testing.assert_array_equal(loaded.ground_truth[key], value)
    assert (folder / "preview_cam0.png").exists() and (folder / "disparity.png").exists()


def test_cli_render_and_bad_size(tmp_path, capsys):
    assert main(["render", str(tmp_path / "s"), "--width", "64", "--height", "48", "--supersample", "1"]) == 0
    assert "rendered demo scene" in capsys.readouterr().out
    assert load(tmp_path / "s").frames.shape == (4, 48, 64)
    assert main(["render", str(tmp_path / "t"), "--width", "60", "--height", "48"]) == 2
    err = capsys.readouterr().err
    assert "--width: expected a multiple of 8 that is at least 24 (LibRaw reads no smaller raw), got 60" in err


def test_cli_inspect_reads_back(tmp_path, capsys):
    assert main(["render", str(tmp_path / "s"), "--width", "64", "--height", "48", "--supersample", "1"]) == 0
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "4 cameras, 64x48, CFA GRBG (read through rawpy)" in out and "tile_disparity" in out
    assert main(["inspect", str(tmp_path / "missing")]) == 2
    assert "missing scene.json" in capsys.readouterr().err


def test_old_folder_gets_tile_surfaces(tmp_path):
    """A folder written before ``tile_surfaces`` existed (its ground-truth NPZ without them) loads with them,
    rebuilt from its per-pixel disparity and objects. Oracle: the rendered ``tile_surfaces``."""
    rig = Rig(width=64, height=48)
    rendered = render(demo_scene(rig), rig, supersample=1)
    folder = save(rendered, tmp_path / "scene", previews=False)
    gt = dict(np.load(folder / "ground_truth.npz"))
    del gt["tile_surfaces"]
    np.savez_compressed(folder / "ground_truth.npz", **gt)
    np.testing.assert_array_equal(load(folder).ground_truth["tile_surfaces"], rendered.tile_surfaces)
