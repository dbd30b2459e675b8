"""Which answers a stereo pair's pipeline gives (``PipelineConfig``: cross-check, off-image windows, confidence
filters) and its per-pixel map. Oracle: the known shift of a band-limited periodic texture (``tests/textures``:
the right image is the left one moved by exactly ``D`` px), and the ideal pair's geometry - the right camera sees
tile tx at 8 tx + 4 - D, so the tiles left of D + 4 px have no match inside the right image."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.textures import fourier_shift, smooth_noise
from tpnet_gpu.io import rigfile
from tpnet_gpu.pipeline import Pipeline, PipelineConfig

D = 13.5
H, W = 96, 160


@pytest.fixture(scope="module")
def pair():
    image = smooth_noise(np.random.default_rng(3), (H, W), 1.5)[0] * 40 + 128
    left, right = fourier_shift(image, D / 2, 0.0), fourier_shift(image, -D / 2, 0.0)
    return np.stack([left, right]).astype(np.float32)


def _pipeline(**config):
    rig = rigfile.load("binocular")
    rig = type(rig)(**{**rig.__dict__, "width": W, "height": H, "_cache": {}}).referenced_to(0)
    return Pipeline(H, W, cfa=None, rig=rig, max_disparity=24.0, backend="warp",
                    config=PipelineConfig(textures=False, **config))


def test_tiles_whose_match_leaves_the_right_image_have_no_value(pair):
    result = _pipeline().process(pair)
    d = result.disparity.numpy()
    x = 8 * np.arange(W // 8) + 4
    off = x - D < 4
    assert np.isnan(d[:, off]).all()
    inner = d[1:-1, ~off][:, :-1]
    assert np.isfinite(inner).mean() > 0.95 and np.nanmax(np.abs(inner - D)) < 0.25
    assert torch.equal(result.checked, torch.isfinite(result.disparity))
    assert (result.confidence.numpy()[np.isnan(d)] == 0).all()
    unchecked = _pipeline(cross_check=False).process(pair).disparity.numpy()
    assert np.isfinite(unchecked[:, off]).mean() > 0.9  # without the checks every tile is answered


def test_confidence_filters(pair):
    pipe = _pipeline(keep_fraction=0.5)
    result = pipe.process(pair)
    full = _pipeline().process(pair)
    kept, answered = int(result.checked.sum()), int(full.checked.sum())
    assert abs(kept - answered / 2) <= 2
    floor = float(result.confidence[result.checked].min())
    assert (full.confidence[full.checked & ~result.checked] <= floor).all()  # the least confident went
    strict = _pipeline(min_confidence=floor + 1e-6).process(pair)
    assert int(strict.checked.sum()) < kept
    for bad in ({"keep_fraction": 0.0}, {"min_confidence": -1}, {"cross_check": 1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            PipelineConfig(**bad)


def test_per_pixel_map_of_a_pair(pair):
    result = _pipeline().process(pair)
    pixels = result.pixels.numpy()
    assert pixels.shape == (H, W)
    inside = pixels[8:-8, int(D) + 12: -8]
    assert np.isfinite(inside).mean() > 0.98 and np.nanmedian(np.abs(inside - D)) < 0.1
    assert _pipeline(per_pixel=False).process(pair).pixels is None


def test_per_pixel_needs_mono_frames():
    rig = rigfile.load("binocular")
    rig = type(rig)(**{**rig.__dict__, "width": W, "height": H, "_cache": {}}).referenced_to(0)
    with pytest.raises(ValueError, match="per_pixel: needs mono frames"):
        Pipeline(H, W, cfa="GRBG", rig=rig, max_disparity=24.0, backend="warp", weights=None,
                 config=PipelineConfig(textures=False, per_pixel=True))
