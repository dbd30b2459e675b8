"""The ``tpnet`` command line: the demo writes its pictures and report, `process` reads a scene folder, bad
input ends with a one-line message. Oracle for the demo: the rendered ground truth."""

import json
import subprocess
import sys

import numpy as np
import tifffile

from tpnet_gpu.cli import main


def test_demo_writes_pictures_and_report(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--width", "160", "--height", "128"]) == 0
    assert "tpnet demo" in capsys.readouterr().out
    for name in ("disparity.png", "error.png", "texture.png", "correlations.png", "ground_truth.png"):
        assert (tmp_path / name).stat().st_size > 0
    report = json.loads((tmp_path / "report.json").read_text())
    flat = report["stats"]["tpnet"]["flat"]
    assert flat["tiles"] > 0 and flat["median_abs"] < 0.2  # against the rendered ground truth


def test_process_scene_folder_and_bad_inputs(tmp_path, capsys):
    assert main(["render", str(tmp_path / "s"), "--width", "96", "--height", "64", "--supersample", "1"]) == 0
    assert main(["process", str(tmp_path / "s"), "--out", str(tmp_path / "o"), "--device", "cpu",
                 "--backend", "warp"]) == 0
    disparity = tifffile.imread(tmp_path / "o" / "disparity.tif")
    assert disparity.shape == (8, 12) and np.isfinite(disparity).any()
    # The Taichi backend (the CPU default) gives the same disparities (same math; float32 rounding differs).
    assert main(["process", str(tmp_path / "s"), "--out", str(tmp_path / "t"), "--device", "cpu"]) == 0
    np.testing.assert_allclose(tifffile.imread(tmp_path / "t" / "disparity.tif"), disparity, atol=1e-3)
    assert (tmp_path / "o" / "texture.png").exists()
    capsys.readouterr()
    assert main(["process", str(tmp_path / "a.dng"), str(tmp_path / "b.dng")]) == 2
    assert "inputs: expected a scene folder or 4 raw files (one per camera), got 2" in capsys.readouterr().err
    assert main(["process", str(tmp_path / "nothing")]) == 2


def test_help_lists_subcommands():
    done = subprocess.run([sys.executable, "-m", "tpnet_gpu.cli", "--help"], capture_output=True, text=True)
    assert done.returncode == 0
    for command in ("demo", "process", "render", "inspect", "dataset", "train", "bench"):
        assert command in done.stdout


def test_command_defaults_are_the_configs():
    # Oracle: the config dataclasses, the one home of every default (tpnet_gpu/config.py).
    from tpnet_gpu import cli
    from tpnet_gpu.config import DatasetSpec, TrainConfig

    parser = cli.build_parser()
    data, train = parser.parse_args(["dataset", "out/x"]), parser.parse_args(["train", "out/x"])
    spec, config = DatasetSpec(), TrainConfig()
    assert (data.scenes, data.width, data.height, data.seed, data.supersample, data.test_fraction) == (
        spec.scenes, spec.width, spec.height, spec.seed, spec.supersample, spec.test_fraction)
    assert (train.epochs, train.batch, train.seed, train.w_mode, train.error_scale) == (
        config.epochs, config.batch, config.seed, config.w_mode, config.error_scale)
