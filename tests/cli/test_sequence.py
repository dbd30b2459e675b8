"""``tpnet process LEFT_DIR RIGHT_DIR``: a video, one folder of frames per camera. Oracle: a photograph moved by a
known shift per frame (exact Fourier shift, as test_answers' pair), so every frame's disparity is known; the
tolerance is test_answers' (median |error| <= 0.1 px inside the frame)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu.cli import main

SHIFTS = (6.4, 6.6, 6.9, 7.1)  # px, the disparity of frames 0..3 (a rig closing in on a wall)


def _video(folder, shifts=SHIFTS):
    import skimage.data

    from tests.textures import fourier_shift

    photo = skimage.data.camera().astype(np.float64)[280:400, 150:350]
    for side, sign in (("left", 0.5), ("right", -0.5)):
        (folder / side).mkdir(parents=True)
        (folder / side / "notes.txt").write_text("not a frame")  # other files are skipped
        for k, d in enumerate(shifts):
            image = np.clip(np.round(fourier_shift(photo, sign * d, 0.0)), 0, 255).astype(np.uint8)
            Image.fromarray(image).save(folder / side / f"{k:04d}.png")
    return [str(folder / "left"), str(folder / "right")]


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    return _video(tmp_path_factory.mktemp("video"))


def _inner_median_error(out, k):
    tiles = tifffile.imread(out / f"frame_{k:05d}" / "disparity.tif")
    return float(np.nanmedian(np.abs(tiles[1:-1, 3:-1] - SHIFTS[k])))


def test_every_frame_is_measured_and_followed_frames_search_less(video, tmp_path, capsys):
    out, searched = tmp_path / "o", tmp_path / "s"
    assert main(["process", *video, "--max-disparity", "12", "--out", str(out), "--no-figures"]) == 0
    for k in range(len(SHIFTS)):
        assert _inner_median_error(out, k) <= 0.1, k
    report = json.loads((out / "sequence.json").read_text())
    assert report["frames"] == len(SHIFTS) and report["failed"] == 0 and report["follow"]
    assert report["per_frame"][2]["files"][1].endswith("right/0002.png")
    said = capsys.readouterr().out
    assert "processed 4 of 4 frames" in said and "following" in said
    # --no-follow searches every frame: the same first frame, more passes on every later one
    assert main(["process", *video, "--max-disparity", "12", "--out", str(searched), "--no-figures",
                 "--no-follow"]) == 0
    other = json.loads((searched / "sequence.json").read_text())
    followed, full = ([r["tile_passes"] for r in rep["per_frame"]] for rep in (report, other))
    assert not other["follow"] and followed[0] == full[0]
    # the frames say which followed: all but the first, none with --no-follow; and the forward motion each
    # measured, k = 1/d before - 1/d now of the wall (measured when written: within 0.0005 of it; 0.001 is 0.05 px
    # of disparity at d = 7)
    assert [r["followed"] for r in report["per_frame"]] == [False, True, True, True]
    assert not any(r["followed"] for r in other["per_frame"])
    k = [r["forward_motion"] for r in report["per_frame"]]
    assert k[0] == 0 and k[1:] == pytest.approx([1 / a - 1 / b for a, b in zip(SHIFTS, SHIFTS[1:])], abs=0.001)
    assert all(f < s for f, s in zip(followed[1:], full[1:])), (followed, full)
    assert sum(followed[1:]) < 0.7 * sum(full[1:]), (followed, full)  # measured: 0.55x (both engines follow)
    assert "searching" in capsys.readouterr().out


def test_a_bad_frame_is_reported_and_the_others_are_written(tmp_path, capsys):
    inputs = _video(tmp_path / "v")
    (tmp_path / "v" / "right" / "0001.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")  # corrupt
    out = tmp_path / "o"
    assert main(["process", *inputs, "--max-disparity", "12", "--out", str(out), "--no-figures"]) == 1
    report = json.loads((out / "sequence.json").read_text())
    assert report["failed"] == 1 and "0001.png" in report["per_frame"][1]["error"]
    assert not (out / "frame_00001").exists()
    for k in (0, 2, 3):  # the frame after the bad one searched afresh, still right
        assert _inner_median_error(out, k) <= 0.1, k
    captured = capsys.readouterr()
    assert "frame 1 (0001.png, 0001.png)" in captured.err and "1 failed" in captured.out


@pytest.mark.parametrize("case, message", [
    ("counts", "expected the same number of frames in every camera folder"),
    ("empty", "expected frame files"),
    ("range", "--max-disparity: required for ordinary images"),  # as for one frame of ordinary images
])
def test_camera_folders_that_do_not_pair_up_are_one_line(tmp_path, capsys, case, message):
    for side in ("left", "right"):
        (tmp_path / side).mkdir()
    image = np.zeros((16, 24), dtype=np.uint8)
    Image.fromarray(image).save(tmp_path / "left" / "0.png")
    if case != "empty":
        for name in ("0.png", "1.png") if case == "counts" else ("0.png",):
            Image.fromarray(image).save(tmp_path / "right" / name)
    out = tmp_path / "o"
    ranged = [] if case == "range" else ["--max-disparity", "4"]
    assert main(["process", str(tmp_path / "left"), str(tmp_path / "right"), *ranged, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and not out.exists()


def test_no_follow_on_one_frame_is_refused(tmp_path, capsys):
    rng = np.random.default_rng(0)
    paths = []
    for name in ("l.png", "r.png"):
        Image.fromarray(rng.integers(0, 256, (16, 24), dtype=np.uint8)).save(tmp_path / name)
        paths.append(str(tmp_path / name))
    assert main(["process", *paths, "--max-disparity", "4", "--out", str(tmp_path / "o"), "--no-follow"]) == 2
    assert "--no-follow: only for a video" in capsys.readouterr().err


def test_a_video_writes_what_one_frame_writes(video, tmp_path):
    # every option of one frame reaches each frame of a video: the same files as `tpnet process LEFT RIGHT`
    options = ["--max-disparity", "12", "--no-figures", "--two-surface", "--per-pixel", "--no-texture"]
    one, out = tmp_path / "one", tmp_path / "video"
    left, right = (sorted(__import__("pathlib").Path(v).glob("*.png"))[0] for v in video)
    assert main(["process", str(left), str(right), "--out", str(one), *options]) == 0
    assert main(["process", *video, "--out", str(out), *options]) == 0
    expected = sorted(p.name for p in one.iterdir())
    assert "foreground.tif" in expected and "depth_px.tif" in expected and "texture.tif" not in expected
    for k in range(len(SHIFTS)):
        assert sorted(p.name for p in (out / f"frame_{k:05d}").iterdir()) == expected, k


def test_a_video_on_ray_is_refused_before_ray_starts(video, tmp_path, capsys):
    assert main(["process", *video, "--max-disparity", "12", "--out", str(tmp_path / "o"), "--ray"]) == 2
    err = capsys.readouterr().err
    assert "--ray: processes scene folders" in err and "Traceback" not in err and not (tmp_path / "o").exists()
