"""The real-pair bench (``tpnet bench real``) and its scoring (``bench/accuracy/real_pairs.py``). Oracles: closed forms of
the half-sine window (its weighted mean of a linear ramp is the ramp at the window's centre: the weights are
symmetric), hand-counted pixels, the PFM layout (bottom row first), and for the bench run the Middlebury ground
truth of one real pair from ``../shared/realdata`` (tsukuba, the smallest): the pipeline must be within the
sub-pixel and gross-error limits below, which the code's own output cannot set."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tpnet_gpu.bench.accuracy import real_pairs as rp

REALDATA = Path(__file__).resolve().parents[4] / "shared" / "realdata"


def test_tile_truth_of_a_ramp_is_the_ramp_at_the_tile_centre():
    h, w = 40, 64
    x = np.arange(w) + 0.5  # pixel centres
    gt = np.tile(10.0 + 0.25 * x, (h, 1))
    truth, spread = rp.tile_truth(gt, (5, 8))
    centres = 10.0 + 0.25 * (8 * np.arange(8) + 4)
    inner = truth[1:-1, 1:-1]  # windows wholly inside the image
    np.testing.assert_allclose(inner, np.tile(centres[1:-1], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(spread[1:-1, 1:-1], 0.25 * 15, atol=1e-12)


def test_tile_truth_needs_half_the_window_known():
    gt = np.full((32, 32), 7.0)
    gt[:, :10] = np.nan  # tile 0's window spans x -4..11: 12 of its 16 columns unknown or outside
    truth, _ = rp.tile_truth(gt, (4, 4))
    assert np.isnan(truth[1, 0]) and truth[1, 2] == pytest.approx(7.0)


def test_scores_count_by_hand():
    truth = np.array([[1.0, 2.0, 3.0, np.nan]])
    spread = np.array([[0.5, 0.5, 2.0, 0.0]])
    estimate = np.array([[1.2, 4.0, np.nan, 9.0]])
    confidence = np.array([[0.9, 0.1, 0.0, 0.5]])
    s = rp.tile_scores(estimate, truth, spread, confidence, 1 / 3)
    assert s["tiles"] == 3 and s["coverage"] == pytest.approx(2 / 3)
    assert s["gross"] == pytest.approx(0.5)  # 1.2 right, 4.0 two px off
    assert s["fronto_median"] == pytest.approx(1.1)  # fronto answered: errors 0.2 and 2.0
    assert s["gross_at_coverage"] == 0.0  # the one most confident answer is the right one
    gt = np.array([[1.0, 1.0], [1.0, np.nan]])
    p = rp.pixel_scores(np.array([[1.5, 2.5], [np.nan, 9.0]]), gt, np.array([[True, True], [True, True]]))
    assert p["pixels"] == 3 and p["coverage"] == pytest.approx(2 / 3)
    assert p["bad1"] == pytest.approx(2 / 3) and p["bad2"] == pytest.approx(1 / 3)  # no answer counts bad
    assert p["avgerr"] == pytest.approx(1.0)


def test_fronto_scatter_removes_each_scenes_own_bias():
    # two scenes whose GT sits +0.3 / -0.2 px off: fronto inliers 0.3 + (-0.1, 0, 0.1) and -0.2 + (-0.05, 0,
    # 0.05); the 2.0 px tile is no inlier, the NaN no answer, the spread-3 tile not fronto. By hand: scatter =
    # median |-0.1, 0, 0.1, -0.05, 0, 0.05| = 0.05; bias = median of the six signed errors = (-0.15 + 0.2) / 2
    truth = np.zeros(9)
    spread = np.array([0.5] * 8 + [3.0])
    error = np.array([0.2, 0.3, 0.4, -0.25, -0.2, -0.15, 2.0, np.nan, 0.1])
    scene = np.array([0, 0, 0, 1, 1, 1, 1, 1, 1])
    s = rp.tile_scores(error, truth, spread, scene=scene)
    assert s["fronto_scatter"] == pytest.approx(0.05) and s["fronto_bias"] == pytest.approx(0.025)
    one = rp.tile_scores(error, truth, spread)  # as one scene: |e - 0.025| -> median (0.225 + 0.275) / 2
    assert one["fronto_scatter"] == pytest.approx(0.25)


def test_either_surface_accepts_either_side_of_an_edge():
    gt = np.full((32, 32), 5.0)
    gt[:, 16:] = 20.0  # tile 1's window (x 4..19) sees 12 columns of 5 and 4 of 20
    estimate = np.full((4, 4), np.nan)
    estimate[1, 1], estimate[2, 1] = 20.0, 12.0
    either = rp.either_correct(estimate, gt)
    assert either[1, 1] and not either[2, 1] and not either[0, 0]


def test_middlebury_2014_folder(tmp_path):
    from PIL import Image

    gt = np.array([[1.0, 2.0, 3.0], [4.0, np.inf, 6.0]], dtype=np.float32)
    with open(tmp_path / "disp0GT.pfm", "wb") as f:  # PFM: bottom row first, negative scale = little-endian
        f.write(b"Pf\n3 2\n-1.0\n" + np.flipud(gt).astype("<f4").tobytes())
    Image.fromarray(np.array([[255, 0, 255], [255, 255, 0]], dtype=np.uint8)).save(tmp_path / "mask0nocc.png")
    (tmp_path / "calib.txt").write_text("cam0=[1 0 0; 0 1 0; 0 0 1]\nndisp=48\n")
    pair = rp.load_pair(tmp_path)
    np.testing.assert_array_equal(pair.gt, [[1, 2, 3], [4, np.nan, 6]])
    np.testing.assert_array_equal(pair.mask, [[True, False, True], [True, True, False]])
    assert pair.max_disparity == 48 and pair.left.name == "im0.png"


@pytest.mark.slow
def test_bench_real_on_tsukuba(tmp_path, capsys):
    pytest.importorskip("cv2")
    if not (REALDATA / "tsukuba" / "meta.json").is_file():
        pytest.skip(f"no real pairs at {REALDATA}")
    from tpnet_gpu import cli

    out = tmp_path / "real.json"
    assert cli.main(["bench", "real", str(REALDATA / "tsukuba"), "--backend", "warp", "--json", str(out),
                     "--figures", str(tmp_path / "figs")]) == 0
    report = json.loads(out.read_text())
    assert "Per tile" in capsys.readouterr().out
    tiles, pixels = report["pooled"]["tiles"], report["pooled"]["pixels_masked"]
    assert set(tiles) == {"tpnet", "engine", "tpnet, no checks", "SGBM"}
    # Middlebury's GT (integer steps on tsukuba): sub-pixel on fronto tiles, few gross answers, the checks only
    # remove answers, per-pixel bad 2.0 near the published range of local methods
    assert tiles["tpnet"]["fronto_median"] < 0.3 and tiles["tpnet"]["gross"] < 0.2
    assert tiles["tpnet"]["coverage"] <= tiles["tpnet, no checks"]["coverage"]
    assert tiles["engine"]["fronto_median"] < 0.3 and tiles["engine"]["gross"] < 0.2  # --method engine
    assert pixels["tpnet per pixel"]["bad2"] < 0.12
    assert (tmp_path / "figs" / "tsukuba.png").stat().st_size > 10_000


def test_bench_real_without_opencv_is_one_line(tmp_path, monkeypatch, capsys):
    import sys

    from tpnet_gpu import cli

    monkeypatch.setitem(sys.modules, "cv2", None)  # import cv2 now fails as if OpenCV were not installed
    assert cli.main(["bench", "real", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "opencv-python-headless" in err and err.count("\n") == 1, err


def test_bench_real_runs_the_weights_it_is_given(tmp_path, capsys):
    # Oracle: weights trained for the quad's lags cannot run on a pair - the pipeline's own refusal, so the
    # tpnet rows did load the file given (before --weights they always ran the shipped mono-pair weights)
    if not (REALDATA / "tsukuba" / "meta.json").is_file():
        pytest.skip(f"no real pairs at {REALDATA}")
    pytest.importorskip("cv2")
    from tpnet_gpu import cli
    from tpnet_gpu.net import infer

    quad = infer.WEIGHTS_DIR / "tpnet_synthetic_v6.pt"
    assert cli.main(["bench", "real", str(REALDATA / "tsukuba"), "--weights", str(quad), "--json", "",
                     "--figures", ""]) == 2
    err = capsys.readouterr().err
    assert f"weights: {quad} were trained for a rig whose layers have lags" in err and err.count("\n") == 1, err
