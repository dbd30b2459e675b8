"""``tpnet demo``: it writes its pictures and report, refreshes its own earlier output and refuses a folder of
other files; weights from ``tpnet train`` are reported by name, weights of another rig refused before the render.
Oracle: the rendered ground truth (flat tiles), and a copy of the shipped weights (same network, same figures)."""

import json
import shutil

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu.cli import main

def test_demo_writes_pictures_and_report(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--width", "160", "--height", "128"]) == 0
    assert "tpnet demo" in capsys.readouterr().out
    for name in ("disparity", "error", "ground_truth", "depth", "confidence", "comparison", "texture_figure",
                 "texture", "correlations", "correlations_figure"):
        with Image.open(tmp_path / f"{name}.png") as image:  # a valid PNG (decoded whole)
            image.load()
    with Image.open(tmp_path / "comparison.png") as image:  # 3 panels of 640 px (docs/outputs.md)
        assert image.size[0] == 3 * 640
    report = json.loads((tmp_path / "report.json").read_text())
    flat = report["stats"]["tpnet"]["flat"]
    assert flat["tiles"] > 0 and flat["median_abs"] < 0.2  # against the rendered ground truth
    # error.tif is the final disparity minus the rendered ground truth (both written beside it)
    np.testing.assert_allclose(tifffile.imread(tmp_path / "error.tif"), tifffile.imread(tmp_path / "disparity.tif")
                               - tifffile.imread(tmp_path / "ground_truth.tif"), atol=1e-6)
    assert "![comparison](comparison.png)" in (tmp_path / "report.md").read_text()
    # run again: the demo refreshes its own output; a folder that also holds another file is refused, untouched
    argv = ["demo", "--out", str(tmp_path), "--width", "160", "--height", "128", "--no-figures"]
    assert main(argv) == 0 and json.loads((tmp_path / "report.json").read_text())["files"]
    assert not (tmp_path / "comparison.png").exists()  # the earlier run's figures go: the folder is this run's
    assert main(argv) == 0  # and again
    (tmp_path / "notes.txt").write_text("mine")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2 and "holds files" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == before and (tmp_path / "notes.txt").read_text() == "mine"


@pytest.mark.slow
def test_demo_weights_a_trained_file_and_one_for_another_rig(tmp_path, capsys, monkeypatch):
    # Oracle: a copy of the shipped quad weights is the network the demo reports (by its file name) and reaches
    # the demo's accuracy; the binocular weights (other layer lags) are refused before anything is rendered.
    from tpnet_gpu.net import infer

    mine = tmp_path / "mine.pt"
    shutil.copy(infer.DEFAULT_WEIGHTS, mine)
    shutil.copy(infer.DEFAULT_WEIGHTS.with_suffix(".json"), mine.with_suffix(".json"))
    argv = ["demo", "--width", "160", "--height", "128", "--no-figures"]
    assert main([*argv, "--out", str(tmp_path / "a"), "--weights", str(mine)]) == 0
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert report["method"] == "TPNET, weights mine.pt" and report["stats"]["tpnet"]["flat"]["median_abs"] < 0.2
    assert {p.name for p in (tmp_path / "a").glob("*.png")} == {"texture.png", "correlations.png"}  # no figures
    capsys.readouterr()
    binocular = infer.WEIGHTS_DIR / "tpnet_binocular_v1.pt"

    def render(*args, **kwargs):
        raise AssertionError("rendered before the weights were checked")

    monkeypatch.setattr("tpnet_gpu.scenes.render", render)
    assert main([*argv, "--out", str(tmp_path / "b"), "--weights", str(binocular)]) == 2
    assert capsys.readouterr().err.startswith("tpnet demo: error: weights:")


def test_a_folder_with_a_crafted_report_is_not_the_demos(tmp_path, capsys):
    """A ``report.json`` nested too deep, or naming no demo scene, makes the folder someone else's: refused in one
    line without ``--overwrite``, untouched (not a RecursionError, not replaced)."""
    for text in ("[" * 100_000, json.dumps({"scene": "mine", "files": ["report.json"]})):
        (tmp_path / "report.json").write_text(text)
        assert main(["demo", "--out", str(tmp_path), "--width", "64", "--height", "48", "--no-figures"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "holds files" in err and (tmp_path / "report.json").read_text() == text
