"""Scene renderer (tpnet_gpu/scenes/render.py). Oracles: the disparity the plane was placed at
(geometry_and_lma.md E: d = f B / (Z p)), the tile processor's own correlation peak on the rendered raws, and
determinism."""

import numpy as np
import pytest

from tests.reference.peaks import centroid_peak
from tpnet_gpu import tables
from tpnet_gpu.camera import Rig
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Optics, Scene, Sensor, Sky, plane, render
from tpnet_gpu.scenes import textures as tx

RIG = Rig(width=128, height=96)


def _plane_scene(d, seed=0):
    rng = np.random.default_rng(seed)
    return Scene([plane(RIG, float(RIG.distance(d)), tx.noise_texture(rng, 512, contrast=0.4))], Sky())


def test_plane_ground_truth_is_exact():
    d = 2.3
    out = render(_plane_scene(d), RIG, supersample=1, noise=False)
    np.testing.assert_allclose(out.tile_disparity, d, rtol=1e-7)  # float32 storage
    np.testing.assert_allclose(out.disparity, d, rtol=1e-6)
    assert np.all(out.tile_spread < 1e-5) and out.tile_confidence.min() > 0.5


@pytest.mark.parametrize("noise", [False, True])
def test_rendered_plane_correlates_at_its_disparity(noise):
    """Correlating the rendered raws at target 0, every pair peaks at -d along its axis
    (geometry_and_lma.md B.2); refining converges to d within 0.05 px (median of the interior tiles), with
    realistic optics and noise."""
    d = 2.3
    out = render(_plane_scene(d), RIG, optics=Optics(), sensor=Sensor(), noise=noise, seed=3)
    frames = out.raws.astype(np.float32) - out.sensor.black_level
    tp = TileProcessor(RIG.height, RIG.width, config=CorrelationConfig(fat_zero=0.0), device="cpu")
    offsets = np.array(tables.QUAD_OFFSETS)
    axes = np.array([offsets[b] - offsets[a] for a, b in tables.QUAD_PAIRS])
    target = np.zeros((RIG.height // 8, RIG.width // 8), dtype=np.float32)
    for _ in range(5):
        corr = tp.process(frames, target).corr.numpy().reshape(*target.shape, 6, 15, 15)
        residual = np.zeros_like(target)
        for ty in range(1, target.shape[0] - 1):
            for tx_ in range(1, target.shape[1] - 1):
                peaks = np.array([centroid_peak(c) for c in corr[ty, tx_]])
                residual[ty, tx_] = np.mean(-(peaks * axes).sum(1) / (axes * axes).sum(1))
        target += residual
    assert np.median(np.abs(target[1:-1, 1:-1] - d)) <= 0.05


def test_rendering_is_deterministic_for_a_seed():
    scene = _plane_scene(1.0)
    a = render(scene, RIG, seed=5).raws
    b = render(scene, RIG, seed=5).raws
    c = render(scene, RIG, seed=6).raws
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)


def test_sky_and_depth_edges_have_low_confidence():
    rng = np.random.default_rng(1)
    fore = plane(RIG, 20.0, tx.edges_texture(rng, 256), centre_px=(64, 48), size_px=(40, 40))
    back = plane(RIG, 400.0, tx.noise_texture(rng, 256, contrast=0.4), centre_px=(64, 80), size_px=(400, 40))
    out = render(Scene([fore, back], Sky()), RIG, supersample=1, noise=False)
    sky = out.tile_disparity == 0
    assert sky.any() and out.tile_confidence[sky].max() < 0.5  # near-uniform sky: no texture
    edge = out.tile_spread > 1.0  # windows mixing the 20 m board and the far plane or sky
    assert edge.any() and out.tile_confidence[edge].max() <= 0.1
    assert out.tile_disparity.max() == pytest.approx(RIG.disparity(20.0), rel=1e-6)


def test_raws_follow_the_sensor_model():
    sensor = Sensor(bits=10, black_level=32)
    out = render(_plane_scene(1.0), RIG, sensor=sensor, supersample=1)
    assert out.raws.dtype == np.uint16 and out.raws.max() <= 1023 and out.raws.min() >= 0
    assert abs(np.median(out.raws) - 32 - 0.4 * 0.7 * (1023 - 32)) < 80  # texture mean 0.4, exposure 0.7


def test_textures_and_bad_input():
    rng = np.random.default_rng(2)
    for texture in (tx.noise_texture(rng, 64), tx.edges_texture(rng, 64), tx.lines_texture(rng, 64),
                    tx.photo_texture("coffee")):
        assert texture.ndim == 3 and texture.shape[2] == 3 and texture.dtype == np.float32
        assert 0.0 <= texture.min() and texture.max() <= 1.0
    with pytest.raises(ValueError, match="name: expected one of .* got 'lena'"):
        tx.photo_texture("lena")
    with pytest.raises(ValueError, match="rig: expected a sensor size in multiples of 8, at least 16x16, got 100x96"):
        render(Scene(), Rig(width=100, height=96))


def test_rendered_plane_peaks_at_its_disparity_in_the_reference():
    """The golden reference correlating a rendered plane at target 0: every pair's integer peak sits at
    -d x the pair's axis (geometry_and_lma.md B.2), for d = 2 px."""
    from tpnet_gpu import reference as ref

    d = 2.0
    out = render(_plane_scene(d), RIG, supersample=2, noise=False, seed=4)
    frames = out.raws.astype(np.float64) - out.sensor.black_level
    centre = np.array([[64.0, 48.0], [40.0, 40.0]])  # two interior tiles (virtual-camera centres), target 0
    clt = [ref.convert_tiles(ref.bayer_planes(frames[cam]), centre)[0] for cam in range(4)]
    offsets = np.array(tables.QUAD_OFFSETS)
    for (a, b) in tables.QUAD_PAIRS:
        corr = ref.correlate(clt[a], clt[b], fat_zero=0.0, colour_weights=(0.0, 0.0, 1.0))
        axis = offsets[b] - offsets[a]
        for tile in corr:
            iy, ix = np.unravel_index(np.argmax(tile), tile.shape)
            assert (ix - 7, iy - 7) == tuple(np.round(-d * axis).astype(int))


def test_window_surfaces_on_hand_made_maps():
    """Oracle: hand-counted windows of a 16x16 image (2x2 tiles; tile (tx, ty) reads x, y in [8 tx - 4, 8 tx + 12),
    clipped to the image: 12x12 pixels here): object 0 at 2 px for x < 8, object 1 slanted (0.1 x px) beyond."""
    from tpnet_gpu.scenes.render import window_surfaces

    x = np.arange(16)[None, :].repeat(16, axis=0)
    objects = np.where(x < 8, 0, 1)
    disparity = np.where(x < 8, 2.0, 0.1 * (x + 0.5))  # pixel-centre disparity of the slanted plane
    out = window_surfaces(disparity, objects, surfaces=3)
    assert out.shape == (2, 2, 3, 3) and out.dtype == np.float32
    for ty in range(2):  # columns 0..11: 8 of object 0, 4 of object 1 (x 8..11); columns 4..15: 4 and 8
        np.testing.assert_allclose(out[ty, 0, :2], [[2 / 3, 2.0, 2.0], [1 / 3, 0.85, 1.15]], rtol=1e-6)
        np.testing.assert_allclose(out[ty, 1, :2], [[2 / 3, 0.85, 1.55], [1 / 3, 2.0, 2.0]], rtol=1e-6)
    assert np.isnan(out[:, :, 2]).all()
    one = window_surfaces(disparity, objects, surfaces=1)  # the largest only
    np.testing.assert_array_equal(one[:, :, 0], out[:, :, 0])


def test_rendered_surfaces_of_a_slanted_plane():
    """Oracle: a plane tilted 70 degrees is one surface: every window has one, of share 1, and its range holds
    the centre ray's disparity and spans the window's spread."""
    rng = np.random.default_rng(3)
    slanted = plane(RIG, 10.0, tx.noise_texture(rng, 256), tilt_deg=70.0)
    out = render(Scene([slanted], Sky()), RIG, supersample=1, noise=False)
    s = out.tile_surfaces[1:-1, 1:-1]
    np.testing.assert_allclose(s[..., 0, 0], 1.0)
    assert np.isnan(s[..., 1:, :]).all()
    np.testing.assert_allclose(s[..., 0, 2] - s[..., 0, 1], out.tile_spread[1:-1, 1:-1], rtol=1e-5)
    gt = out.tile_disparity[1:-1, 1:-1]
    assert np.all((s[..., 0, 1] <= gt + 1e-5) & (gt - 1e-5 <= s[..., 0, 2])) and out.tile_spread.min() > 0.5


def test_mono_sensor_records_the_luminance():
    """Oracle: Rec. 709 luminance (0.2126 R + 0.7152 G + 0.0722 B) of a flat colour, through the sensor's exposure
    and black level (noise off); a Bayer sensor records each pixel's own colour instead."""
    from tpnet_gpu.scenes.render import expose  # noqa: PLC0415

    rgb = np.array([0.8, 0.3, 0.1])
    planes = np.broadcast_to(rgb[:, None, None], (3, 4, 6)).copy()
    sensor = Sensor(cfa=None)
    span = sensor.white_level - sensor.black_level
    mono = expose(planes, sensor, None)
    luma = 0.2126 * 0.8 + 0.7152 * 0.3 + 0.0722 * 0.1
    assert mono.shape == (4, 6) and (mono == round(luma * sensor.exposure * span + sensor.black_level)).all()
    bayer = expose(planes, Sensor(cfa="GRBG"), None)  # row 0: G R G R ..., row 1: B G B G ...
    assert bayer[0, 1] == round(0.8 * sensor.exposure * span + sensor.black_level)
    assert bayer[1, 0] == round(0.1 * sensor.exposure * span + sensor.black_level)
