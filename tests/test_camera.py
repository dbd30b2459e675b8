"""Rig model (tpnet_gpu/camera.py) against the spec's closed forms (geometry_and_lma.md A.2, A.5, E), round
trips, and ray geometry (a world point lies on the ray of its own projection)."""

import numpy as np
import pytest

from tpnet_gpu import tables
from tpnet_gpu.camera import Rig

RNG = np.random.default_rng(60)
DISTORTED = Rig(distortion=(0.02, -0.05, 0.03, 0.0, -0.004, 0.0, 0.0), principal_points=((1290, 970), (1300, 965), (1296, 968), (1299, 971)),
                extrinsics=(1e-3, -2e-3, 5e-4, 1e-3, 3e-4, -1e-3, 2e-3, -1e-3, 5e-4, 0.0, 1e-3, -5e-4, 2e-4),
                rolls_deg=(0.1, -0.2, 0.05, 0.0))


def test_ideal_rig_reduces_to_c_minus_d_r():
    rig = Rig()
    centre = RNG.uniform(0, 2000, size=(10, 2))
    d = RNG.uniform(-2, 20, size=10)
    want = centre[:, None, :] - d[:, None, None] * np.array(tables.QUAD_OFFSETS)
    np.testing.assert_allclose(rig.port_coordinates(centre, d), want, atol=1e-9)


def test_tile_centres_grid_and_nan():
    rig = Rig(width=64, height=48)
    d = np.full((6, 8), 2.0)
    d[1, 2] = np.nan
    centres = rig.tile_centres(d)
    assert centres.shape == (48, 4, 2)
    np.testing.assert_allclose(centres[9, 0], [8 * 1 + 4 + 1.0, 8 * 1 + 4 + 1.0])  # cam 0 at c + d/2
    assert np.isnan(centres[1 * 8 + 2]).all()


def test_paper_figure_five_pixels_at_100_m():
    rig = Rig()
    assert rig.disparity(100.0) == pytest.approx(5.28, abs=0.01)  # "~5 px at 100 m", 258 mm baseline
    assert rig.distance(rig.disparity(37.0)) == pytest.approx(37.0)


def test_distortion_round_trip():
    xy = RNG.uniform(-1300, 1300, size=(100, 2))
    np.testing.assert_allclose(DISTORTED.distort(DISTORTED.undistort(xy)), xy, atol=1e-8)
    np.testing.assert_allclose(DISTORTED.undistort(DISTORTED.distort(xy)), xy, atol=1e-8)
    # k(1) = 1: a point at the normalisation radius keeps its radius (A.4)
    r = DISTORTED.distortion_radius_mm / DISTORTED.pixel_size_mm
    assert np.linalg.norm(DISTORTED.distort([[r, 0.0]])) == pytest.approx(r)


def test_world_image_round_trip():
    pixels = RNG.uniform(0, 2000, size=(50, 2))
    d = RNG.uniform(0.5, 30, size=50)
    for rig in (Rig(), DISTORTED):
        world = rig.image_to_world(pixels, d)
        back, d_back = rig.world_to_image(world)
        np.testing.assert_allclose(back, pixels, atol=1e-7)
        np.testing.assert_allclose(d_back, d, atol=1e-10)


def test_each_camera_ray_passes_through_the_world_point():
    # Project world points into every sensor (port_coordinates), cast that pixel's ray back: it must pass
    # through the point (distortion, principal points, rotations and zoom all inverted consistently).
    pixels = RNG.uniform(200, 1800, size=(20, 2))
    d = RNG.uniform(1, 20, size=20)
    world = DISTORTED.image_to_world(pixels, d)
    ports = DISTORTED.port_coordinates(pixels, d)
    lenses = DISTORTED.lens_positions()
    for cam in range(4):
        ray = DISTORTED.pixel_rays(cam, ports[:, cam])
        t = (world[:, 2] - lenses[cam, 2]) / ray[:, 2]
        hit = lenses[cam] + t[:, None] * ray
        np.testing.assert_allclose(hit, world, atol=1e-6 * np.abs(world).max())


def test_azimuth_moves_the_image_left():
    # A.5 small-angle meaning: azimuth + (looks right) -> x' = x - alpha F.
    alpha = 1e-4
    rig = Rig(extrinsics=(0, 0, 0, alpha, 0, 0, 0, 0, 0, 0, 0, 0, 0))
    shift = rig.port_coordinates([1296.0, 968.0], 0.0)[0] - np.array([1296.0, 968.0])
    np.testing.assert_allclose(shift, [-alpha * rig.focal_px, 0.0], atol=1e-6)


def test_json_round_trip_and_bad_values():
    assert Rig.from_json(DISTORTED.to_json()) == DISTORTED
    with pytest.raises(ValueError, match="distortion: expected 7 terms"):
        Rig(distortion=(0.1,))
    with pytest.raises(ValueError, match="baseline_mm: expected a positive length, got 0"):
        Rig(baseline_mm=0)
    with pytest.raises(ValueError, match=r"rig: unknown keys \['fov'\]"):
        Rig.from_json({"fov": 60})
