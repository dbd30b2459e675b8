"""Texture reference (tile_processor.md §7.3, §7.4) against independent oracles: scipy.ndimage for the demosaic
filters, hand values for the fade and the shot compression, and physical facts of a scene the cameras agree on
(alpha 1, colour = the scene)."""

import numpy as np
import pytest
from scipy import ndimage

from tests.textures import mosaic, smooth_noise
from tpnet_gpu import reference as ref
from tpnet_gpu import tables
from tpnet_gpu.reference import texture as tex

RNG = np.random.default_rng(40)


@pytest.mark.parametrize("filt", [tex.RB_FILTER, tex.G_FILTER], ids=["rb", "g"])
def test_demosaic_filters_the_interior_only(filt):
    u = RNG.normal(size=(16, 16))
    out = tex.demosaic_interior(u, filt)
    np.testing.assert_allclose(out[1:15, 1:15], ndimage.correlate(u, filt)[1:15, 1:15], atol=1e-12)
    np.testing.assert_array_equal(out[0], u[0])
    np.testing.assert_array_equal(out[:, 15], u[:, 15])


def test_shot_compression_is_continuous():
    v = np.array([-5.0, 0.0, 10.0, 10.0 + 1e-9, 36.0])
    np.testing.assert_allclose(tex.shot_compress(v, 3.0, 10.0), [-15 / np.sqrt(10), 0, 3 * np.sqrt(10),
                                                                   3 * np.sqrt(10), 18.0], rtol=1e-8)


def test_alpha_fade_cases():
    f = tex.fade_ramp()
    assert f[0] < 0.01 and f[15] > 0.99
    np.testing.assert_allclose(tex.alpha_fade(True, False, False, False)[:, 3], f[::-1])  # ramp up towards north
    np.testing.assert_allclose(tex.alpha_fade(False, True, False, False)[5], f)  # towards east
    corner = tex.alpha_fade(False, True, True, False)  # east + south: max of both ramps
    assert corner[0, 0] == pytest.approx(f[0]) and corner[15, 0] == pytest.approx(f[15])
    for flags in [(False,) * 4, (True, False, True, False), (True, True, True, False), (True,) * 4]:
        np.testing.assert_array_equal(tex.alpha_fade(*flags), 1.0)


def _agreeing_scene(cfa, size=64, sigma=3.0):
    colour = 1000 + 300 * smooth_noise(RNG, (size, size), sigma, channels=3)
    frame = mosaic(colour) if cfa else colour[2]
    planes = ref.bayer_planes(frame) if cfa else frame[None]
    clt, _ = ref.convert_tiles(planes, ref.tile_centres(size // 8, size // 8).reshape(-1, 2))
    return colour, np.repeat(clt[:, None], 4, axis=1)  # 4 identical cameras


@pytest.mark.parametrize("cfa", [True, False], ids=["bayer", "mono"])
def test_agreeing_cameras_give_alpha_one_and_the_scene(cfa):
    colour, clt = _agreeing_scene(cfa)
    size = colour.shape[-1]
    rgba = tex.texture_tiles(clt, tables.QUAD_OFFSETS)
    image = tex.texture_image(rgba.reshape(8, 8, -1, 16, 16), np.ones((8, 8), bool), size, size,
                              output_gain=4.0 if cfa else 1.0)
    inner = (slice(8, -8), slice(8, -8))
    np.testing.assert_allclose(image[-1][inner], 1.0 + tables.TEXTURE_WEIGHT_FLOOR, atol=1e-9)
    truth = colour[[0, 1, 2]] if cfa else colour[2:3]
    # A low-passed rendition of a sigma 3 px scene. Measured: mean |error| 0.5-1.8 % of the range, max 2 % (mono,
    # G) to 9 % (R, B: the zero-filled quarter-density lattices alias near Nyquist, which the soft LPF leaves).
    for k in range(truth.shape[0]):
        error = np.abs(image[k][inner] - truth[k][inner])
        assert error.mean() <= 0.025 * np.ptp(truth[k]) and error.max() <= 0.1 * np.ptp(truth[k])


def test_a_disagreeing_camera_is_outvoted():
    colour, clt = _agreeing_scene(True)
    clt[:, 3] *= 1.5  # camera 3 sees a brighter scene: it must lose weight, the colour stay with the others
    rgba = tex.texture_tiles(clt, tables.QUAD_OFFSETS)
    image = tex.texture_image(rgba.reshape(8, 8, 4, 16, 16), np.ones((8, 8), bool), 64, 64)
    inner = (slice(8, -8), slice(8, -8))
    assert np.abs(image[2][inner] - colour[2][inner]).mean() < 0.02 * colour[2].mean()
    assert 0.5 < image[3][inner].mean() < 0.9  # three cameras agree, one does not
