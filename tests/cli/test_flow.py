"""``tpnet flow`` (tpnet_gpu/cli/flow.py). Oracle: PNG frames of a texture moved by a known sub-pixel shift per
frame (an exact Fourier shift, then 16-bit quantisation): the written flow TIFFs hold that shift; bad input is a
one-line error with exit status 2."""

import subprocess
import sys

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu import cli
from tpnet_gpu.cli.flow import flow_colours
from tpnet_gpu.scenes import textures as tx

STEP = (1.5, -0.5)  # px per frame


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    from scipy import ndimage

    folder = tmp_path_factory.mktemp("seq")
    img = ndimage.gaussian_filter(tx.noise_texture(np.random.default_rng(3), 256)[..., 1].astype(np.float64), 0.7,
                                  mode="wrap")
    fy, fx = np.meshgrid(np.fft.fftfreq(256), np.fft.fftfreq(256), indexing="ij")
    for k in range(3):
        moved = np.fft.ifft2(np.fft.fft2(img) * np.exp(-2j * np.pi * k * (fx * STEP[0] + fy * STEP[1]))).real
        scaled = (moved[:100, :130] - img.min()) / (img.max() - img.min()) * 60000
        Image.fromarray(scaled.astype(np.uint16)).save(folder / f"f{k}.png")
    return folder


def _check(path):
    flow = tifffile.imread(path)
    assert flow.shape == (2, 13, 17)  # ceil(100 / 8), ceil(130 / 8) tiles, the padding cropped off
    np.testing.assert_allclose(np.nanmedian(flow, axis=(1, 2)), STEP, atol=0.02)


def test_flow_of_two_images(sequence, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["flow", str(sequence / "f0.png"), str(sequence / "f1.png"), "--out", str(out),
                     "--backend", "warp"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["confidence.tif", "flow.png", "flow.tif", "flow_figure.png"]
    _check(out / "flow.tif")
    assert "1 frame pair" in capsys.readouterr().out


def test_flow_of_a_sequence_folder(sequence, tmp_path):
    out = tmp_path / "out"
    assert cli.main(["flow", str(sequence), "--out", str(out), "--backend", "warp", "--no-figures"]) == 0
    assert not list(out.glob("*_figure.png"))
    for k in (0, 1):
        _check(out / f"flow_{k:04d}.tif")
        assert (out / f"flow_{k:04d}.png").exists() and (out / f"confidence_{k:04d}.tif").exists()


@pytest.mark.parametrize("argv, message", [
    (["{seq}/f0.png"], "expected two frames or a sequence folder"),
    (["{seq}/f0.png", "{seq}/f1.png", "--init", "1,x"], "--init: expected X,Y"),
    (["{seq}/f0.png", "{seq}/missing.png"], "missing.png"),
])
def test_bad_inputs_are_one_line(sequence, tmp_path, capsys, argv, message):
    argv = [a.format(seq=sequence) for a in argv]
    assert cli.main(["flow", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tpnet flow: error:") and message in err and "\n" not in err


def test_help_lists_flow():
    done = subprocess.run([sys.executable, "-m", "tpnet_gpu.cli", "flow", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "sequence" in done.stdout


def test_flow_colours_direction_and_length():
    flow = np.array([[[1.0, 0.0], [-2.0, 0.0], [np.nan, np.nan]]])
    rgb = flow_colours(flow)
    assert tuple(rgb[0, 0]) == (128, 0, 0)  # +x: red at half the longest length
    assert tuple(rgb[0, 1]) == (0, 255, 255)  # -x: cyan, the longest
    assert tuple(rgb[0, 2]) == (0, 0, 0)  # NaN: black
