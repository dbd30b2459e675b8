"""A rig moving between frames (tpnet_gpu/scenes/motion.py). Oracles: pinhole geometry by hand - a sideways
translation T of the rig moves a fronto-parallel plane at distance Z by -F T / Z px (F = focal / pixel), a pan by
a small angle a moves points at infinity by about F tan(a); and the renderer itself: the moved scene rendered
at the identity motion is the scene rendered unmoved, bit for bit."""

import numpy as np
import pytest

from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes import Scene, Sky, plane, render
from tpnet_gpu.scenes import textures as tx
from tpnet_gpu.scenes.motion import RigMotion, moved_scene, tile_flow

RIG = Rig(width=64, height=48)


def _wall(distance_m=30.0):
    return Scene([plane(RIG, distance_m, tx.noise_texture(np.random.default_rng(0), 256, contrast=0.4))], Sky())


def test_sideways_translation_moves_a_wall_by_f_t_over_z():
    scene, t_mm, z_m = _wall(30.0), 120.0, 30.0
    for cam in (0, 3):
        flow = tile_flow(scene, RIG, RigMotion(translation=(t_mm, 0.0, 0.0)), cam)
        np.testing.assert_allclose(flow[..., 0], -RIG.focal_px * t_mm / (z_m * 1000.0), rtol=1e-9)
        np.testing.assert_allclose(flow[..., 1], 0.0, atol=1e-9)


def test_pan_moves_the_sky_by_f_tan_angle_at_the_centre():
    angle = 0.003
    flow = tile_flow(Scene([], Sky()), RIG, RigMotion(rotation=(0.0, angle, 0.0)), 0)
    centre = flow[RIG.height // 16, RIG.width // 16]  # the tile at (36, 28): 4 px from the optical centre
    assert abs(centre[0]) == pytest.approx(RIG.focal_px * np.tan(angle), rel=1e-3)
    assert abs(centre[1]) < 0.01


def test_identity_motion_renders_the_same_frame():
    scene = _wall()
    a = render(scene, RIG, supersample=1, seed=3)
    b = render(moved_scene(scene, RigMotion()), RIG, supersample=1, seed=3)
    np.testing.assert_array_equal(a.raws, b.raws)


def test_moved_scene_agrees_with_the_ground_truth_flow():
    """Rendered: the noise-free luminance of the moved wall at p + flow(p) equals the unmoved one at p, so the
    object map moves with the flow (the renderer and tile_flow agree on the direction)."""
    scene, motion = _wall(10.0), RigMotion(translation=(20.0, 0.0, 0.0))  # -F T / Z = -4.09 px
    flow = tile_flow(scene, RIG, motion, 0)
    assert flow[..., 0].mean() < -4.0
    a = render(scene, RIG, supersample=1, noise=False).raws[0].astype(float)
    b = render(moved_scene(scene, motion), RIG, supersample=1, noise=False).raws[0].astype(float)
    shift = int(round(float(flow[..., 0].mean())))  # -4: whole pixels, even, so the Bayer phase is kept
    rows = slice(8, 40)
    diff_moved = np.abs(b[rows, 16 + shift:48 + shift] - a[rows, 16:48]).mean()
    diff_still = np.abs(b[rows, 16:48] - a[rows, 16:48]).mean()
    assert diff_moved < 0.5 * diff_still
