"""The rendered-pair suite (``bench/accuracy/rendered_pairs.py``) and its bench (``tpnet bench rendered_pairs``). Oracles:

* the documented contract: unknown cases are refused by name, one ``realdata`` folder per case that
  ``real_pairs.load_pair`` reads, ``MAX_DISPARITY`` kept, GT inside the documented 6..60 px;
* geometry: the background is a plane seen at 8 px at the image centre and tilted about the horizontal axis only,
  so its disparity - the smallest of each row, every object being nearer - is affine in the row and constant
  along it (a plane's disparity is affine in the image coordinates), 8 px at y = H / 2 (+-1/64 px, the
  gt.png step); camera cases share the layout (same GT) and touch only the right camera (same left image);
* for the bench run, the rendered GT against the pipeline's estimate on the "clean" case: its fronto-parallel tiles
  within 0.25 px (median; measured 0.011 px at 128x96 - the code's own output cannot set that GT), and the report
  layout of ``tpnet bench real`` (``bench/accuracy/bench_real.py``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tpnet_gpu.bench.accuracy import real_pairs as rp
from tpnet_gpu.bench.accuracy import rendered_pairs as suite

SIZE = (96, 64)  # width, height
TILE_METHODS = {"tpnet", "engine", "tpnet, no checks", "SGBM"}
PIXEL_METHODS = {"tpnet per pixel", "tpnet tile cells", "SGBM"}


def test_case_scene_rejects_an_unknown_case_naming_it():
    with pytest.raises(ValueError, match=r"^case: expected one of \[.*'clean'.*\], got 'nope'"):
        suite.case_scene("nope", suite.pair_rig(*SIZE), 0)


def test_pair_rig_is_the_binocular_rig_cut_to_size():
    rig = suite.pair_rig(*SIZE)
    assert (rig.width, rig.height) == SIZE and rig.cams == 2 and rig.is_ideal()
    np.testing.assert_allclose(np.diff(rig.offsets_array(), axis=0), [[1.0, 0.0]])  # camera 1 one baseline right


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("suite")
    cases = ("clean", "vertical", "occlusion")
    folders = suite.write_suite(root, cases=cases, size=SIZE, seed=3, supersample=1)
    return root, cases, folders


def test_write_suite_writes_one_readable_folder_per_case(written):
    root, cases, folders = written
    assert folders == [root / case for case in cases]
    assert sorted(p.name for p in root.iterdir()) == sorted(cases)
    for folder in folders:
        pair = rp.load_pair(folder)
        assert pair.name == folder.name and pair.max_disparity == suite.MAX_DISPARITY
        assert pair.gt.shape == pair.mask.shape == SIZE[::-1] and pair.left.is_file() and pair.right.is_file()
        assert np.isfinite(pair.gt).all()  # the background fills the view: no sky
        assert 6.0 <= pair.gt.min() and pair.gt.max() <= 60.0 < pair.max_disparity
        assert 0.5 < pair.mask.mean() < 1.0  # the left edge strip and the objects' shadows are occluded
        assert "seed 3" in json.loads((folder / "meta.json").read_text())["source"]


def test_background_is_the_tilted_plane_at_8_px(written):
    _, _, folders = written
    gt = rp.load_pair(folders[0]).gt
    height = gt.shape[0]
    rows = np.arange(height) + 0.5  # pixel centres
    background = gt.min(axis=1)  # per row: the farthest surface
    slope, offset = np.polyfit(rows, background, 1)
    assert np.abs(background - (slope * rows + offset)).max() <= 1 / 64
    assert slope * height / 2 + offset == pytest.approx(8.0, abs=1 / 64)
    assert abs(slope) > 1e-4  # tilted: not a constant


def _read(path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im).copy()


def test_camera_cases_share_the_layout_and_the_left_camera(written):
    _, _, (clean, vertical, occlusion) = written
    a, b, c = (rp.load_pair(f) for f in (clean, vertical, occlusion))
    np.testing.assert_array_equal(_read(a.left), _read(b.left))  # the vertical offset is the right camera's
    assert np.mean(_read(a.right) != _read(b.right)) > 0.5
    np.testing.assert_array_equal(np.isfinite(a.gt), np.isfinite(b.gt))
    np.testing.assert_allclose(a.gt, b.gt, atol=1e-12)
    assert c.gt.max() > 40.0 > a.gt.max()  # the occlusion case's near boards: 40..60 px


def test_bench_rendered_pairs_clean_case(tmp_path, capsys):
    pytest.importorskip("cv2")
    from tpnet_gpu import cli

    out, pairs = tmp_path / "rendered.json", tmp_path / "pairs"
    assert cli.main(["bench", "rendered_pairs", "--cases", "clean", "--size", "128x96", "--pairs", str(pairs),
                     "--json", str(out)]) == 0
    assert "Per tile" in capsys.readouterr().out
    report = json.loads(out.read_text())
    assert {"bench", "cases", "size", "seed", "pairs", "per_scene", "pooled", "machine", "table"} <= set(report)
    assert report["bench"] == "rendered_pairs" and report["cases"] == ["clean"] and report["size"] == [128, 96]
    assert report["seed"] == 0 and report["pairs"] == [str(pairs / "clean")] and set(report["per_scene"]) == {"clean"}
    scene = report["per_scene"]["clean"]
    assert set(scene["tiles"]) == set(report["pooled"]["tiles"]) == TILE_METHODS
    assert set(scene["pixels"]) == PIXEL_METHODS
    kept = rp.load_pair(pairs / "clean")  # --pairs keeps what was scored
    assert scene["tiles"]["tpnet"]["tiles"] == (96 // 8) * (128 // 8)
    assert scene["pixels"]["SGBM"]["pixels"] == int((np.isfinite(kept.gt) & kept.mask).sum())
    ours = scene["tiles"]["tpnet"]
    assert ours["fronto_tiles"] >= 10 and ours["fronto_median"] < 0.25, ours
    assert 0.0 < ours["coverage"] <= scene["tiles"]["tpnet, no checks"]["coverage"]  # the checks only remove


def test_bench_rendered_pairs_refuses_unknown_cases(capsys):
    pytest.importorskip("cv2")  # the bench asks for OpenCV before it reads --cases
    from tpnet_gpu import cli
    from tpnet_gpu.bench.accuracy import bench_rendered_pairs

    for cases in ("nope", "clean,nope", ","):
        with pytest.raises(SystemExit) as exit_:
            bench_rendered_pairs.main(["--cases", cases, "--json", ""])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert "error: --cases: expected some of clean," in err and repr(cases) in err, err
    assert cli.main(["bench", "rendered_pairs", "--cases", "nope", "--json", ""]) == 2
    assert "--cases" in capsys.readouterr().err


@pytest.mark.parametrize("option, value", [("--size", "128x96,64x48"), ("--size", "100x96"), ("--seed", "-1")])
def test_bench_rendered_pairs_refuses_a_bad_option_naming_it(capsys, option, value):
    pytest.importorskip("cv2")
    from tpnet_gpu.bench import common
    from tpnet_gpu.bench.accuracy import bench_rendered_pairs

    assert common.run(bench_rendered_pairs.main, [option, value, "--json", ""]) == 2
    assert option in capsys.readouterr().err


def test_gt_step_rounds_the_stored_gt_like_the_real_pairs(written, tmp_path):
    """Oracle: the definition of rounding - every stored value a multiple of the step, within half a step of the
    exact GT of the same seed (gt.png keeps 1/64 px: each within 1/128 more)."""
    _, _, folders = written
    exact = rp.load_pair(folders[0]).gt
    (folder,) = suite.write_suite(tmp_path, cases=("clean",), size=SIZE, seed=3, supersample=1, gt_step=0.25)
    stepped = rp.load_pair(folder).gt
    tol = 1 / 128 + 1e-9  # gt.png's own rounding, on both
    assert np.abs(stepped - exact).max() <= 0.125 + 2 * tol  # within half a step of the exact GT
    assert np.abs(stepped / 0.25 - np.round(stepped / 0.25)).max() * 0.25 <= tol  # on the step's multiples
    assert len(np.unique(stepped)) < len(np.unique(exact)) / 4
    with pytest.raises(ValueError, match="gt_step"):
        suite.write_suite(tmp_path / "no", cases=("clean",), size=SIZE, gt_step=0.0)
