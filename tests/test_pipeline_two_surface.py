"""``PipelineConfig(two_surface=True)`` (tpnet_gpu/pipeline.py) and ``tpnet process --two-surface``. Oracle: the
synthetic board-over-background frame of tests/disparity/test_two_surface.py (known D_FG, D_BG either side of a
vertical edge); the pipeline's other outputs must be those of a run without the option (its extra passes must
not overwrite them)."""

import numpy as np
import tifffile
import torch

from tests.disparity.test_two_surface import D_BG, D_FG, SIZE, _edge_frames
from tpnet_gpu import cli
from tpnet_gpu.pipeline import Pipeline, PipelineConfig


def test_pipeline_reports_both_surfaces_and_keeps_its_outputs():
    frames = _edge_frames()
    plain = Pipeline(SIZE, SIZE, cfa=None, backend="warp", device="cpu", config=PipelineConfig(textures=True))
    both = Pipeline(SIZE, SIZE, cfa=None, backend="warp", device="cpu",
                    config=PipelineConfig(textures=True, two_surface=True))
    a, b = plain.process(frames), both.process(frames)
    assert a.surfaces is None
    for name in ("disparity", "confidence", "valid", "texture"):
        torch.testing.assert_close(getattr(b, name), getattr(a, name), equal_nan=True, msg=name)
    fg, bg = b.surfaces.foreground[1:-1, 6].numpy(), b.surfaces.background[1:-1, 6].numpy()
    two = np.isfinite(fg)
    assert two.mean() >= 0.8
    assert np.median(np.abs(fg[two] - D_FG)) < 0.4 and np.median(np.abs(bg[two] - D_BG)) < 0.4


def test_process_two_surface_writes_foreground_and_background(tmp_path, capsys):
    frames = _edge_frames()
    paths = []
    for cam, frame in enumerate(frames):  # 16-bit mono TIFFs, one per camera of the quad rig
        path = tmp_path / f"cam{cam}.tif"
        tifffile.imwrite(path, np.clip(frame, 0, 65535).astype(np.uint16))
        paths.append(str(path))
    out = tmp_path / "out"
    assert cli.main(["process", *paths, "--rig", "quad", "--max-disparity", "12", "--two-surface", "--out",
                     str(out), "--backend", "warp"]) == 0
    fg, bg = tifffile.imread(out / "foreground.tif"), tifffile.imread(out / "background.tif")
    assert fg.shape == bg.shape == (SIZE // 8, SIZE // 8)
    column = np.isfinite(fg[1:-1, 6])
    assert column.mean() >= 0.8 and np.median(np.abs(fg[1:-1, 6][column] - D_FG)) < 0.4
    assert (out / "w_foreground.tif").exists() and "foreground" in capsys.readouterr().out
