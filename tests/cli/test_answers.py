"""``tpnet process`` on a stereo pair: the per-pixel files and the options that choose which answers come out.
Oracle: a photograph moved by a known shift (exact Fourier shift, as test_cli's end-to-end pair) and the rig's
depth formula Z = f B / (d p) for the depth file."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu.cli import main

D = 6.4


@pytest.fixture(scope="module")
def photo_pair(tmp_path_factory):
    import skimage.data

    from tests.textures import fourier_shift

    folder = tmp_path_factory.mktemp("pair")
    photo = skimage.data.camera().astype(np.float64)[280:400, 150:350]
    paths = []
    for name, shift in (("left.png", D / 2), ("right.png", -D / 2)):
        image = np.clip(np.round(fourier_shift(photo, shift, 0.0)), 0, 255).astype(np.uint8)
        Image.fromarray(image).save(folder / name)
        paths.append(str(folder / name))
    return paths


def test_per_pixel_files(photo_pair, tmp_path):
    from tpnet_gpu.outputs import pointcloud
    from tpnet_gpu.io import rigfile

    out = tmp_path / "o"
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(out), "--per-pixel"]) == 0
    pixels = tifffile.imread(out / "disparity_px.tif")
    assert pixels.shape == (120, 200) and pixels.dtype == np.float32
    inner = pixels[8:-8, 20:-8]
    assert np.isfinite(inner).mean() > 0.95 and np.nanmedian(np.abs(inner - D)) <= 0.1
    rig = rigfile.load("binocular")
    depth = tifffile.imread(out / "depth_px.tif")
    finite = np.isfinite(pixels) & (pixels > 0)
    np.testing.assert_allclose(depth[finite], rig.distance(pixels[finite].astype(np.float64)), rtol=1e-5)
    # the left-right check: what both cameras see passes, the strip whose match leaves the right image does not
    # (its pixels carry the fill); the point cloud has the measured pixels only
    measured = np.asarray(Image.open(out / "measured_px.png")) == 255
    assert measured[8:-8, 20:-8].mean() > 0.95 and not measured[:, : int(D)].any()
    header = (out / "points_px.ply").read_bytes()[:400].decode("ascii", "replace")
    assert f"element vertex {int((finite & measured).sum())}" in header
    assert (out / "disparity_px.png").is_file()


def test_default_has_per_pixel_disparity_only(photo_pair, tmp_path):
    out = tmp_path / "o"
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(out), "--no-figures"]) == 0
    assert (out / "disparity_px.tif").is_file() and not (out / "depth_px.tif").exists()


def test_keep_fraction_halves_the_answers(photo_pair, tmp_path):
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "a"), "--no-figures"]) == 0
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "b"), "--no-figures",
                 "--keep-fraction", "0.5"]) == 0
    full, half = (np.isfinite(tifffile.imread(tmp_path / n / "disparity.tif")).sum() for n in "ab")
    assert abs(half - full / 2) <= 2


@pytest.mark.parametrize("option, value, message", [
    ("--keep-fraction", "0", "keep_fraction: expected a number in (0, 1]"),
    ("--min-confidence", "-1", "min_confidence: expected a finite number >= 0"),
])
def test_bad_answer_options_are_one_line(photo_pair, tmp_path, capsys, option, value, message):
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "o"), option, value]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_method_tpnet_runs_the_mono_weights_and_says_so(photo_pair, tmp_path, capsys):
    """An image pair runs the engine by default (the mono weights ship on request: the closing line says the
    engine and the log says why); ``--method tpnet`` runs TPNET with them and names them."""
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "a"), "--no-figures"]) == 0
    out = capsys.readouterr()
    assert "disparity engine" in out.out.splitlines()[-1] and "on request only" in out.err
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "t"), "--no-figures",
                 "--method", "tpnet"]) == 0
    assert "TPNET, weights tpnet_binocular_mono_v1.pt" in capsys.readouterr().out.splitlines()[-1]


def test_method_engine_says_so(photo_pair, tmp_path, capsys):
    """``--method engine`` runs no network and says so on its closing line; with ``--weights`` it is refused in one
    line naming the weights, and nothing is written."""
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "e"), "--no-figures",
                 "--method", "engine"]) == 0
    assert "disparity engine" in capsys.readouterr().out.splitlines()[-1]
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(tmp_path / "w"), "--method",
                 "engine", "--weights", str(tmp_path / "any.pt")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "weights" in err, err
    assert not (tmp_path / "w").exists()


def test_no_texture_writes_no_texture_and_the_same_disparity(photo_pair, tmp_path):
    # the texture pass comes after the disparity (pipeline.process): the maps are bit for bit those with it
    out, plain = tmp_path / "o", tmp_path / "p"
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(out), "--no-figures",
                 "--no-texture"]) == 0
    assert main(["process", *photo_pair, "--max-disparity", "12", "--out", str(plain), "--no-figures"]) == 0
    assert not any((out / name).exists() for name in ("texture.tif", "texture.png"))
    assert (plain / "texture.tif").is_file()
    np.testing.assert_array_equal(tifffile.imread(out / "disparity.tif"), tifffile.imread(plain / "disparity.tif"))
    headers = [(f / "points.ply").read_bytes()[:600].decode("ascii", "replace") for f in (out, plain)]
    assert "property uchar red" not in headers[0] and "property uchar red" in headers[1]
