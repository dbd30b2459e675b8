"""Curved objects (``scenes.curved``): oracles are geometry - a hit lies on the surface, a ray hits exactly when
its distance from the centre (axis) is below the radius, the front point sits at the placed distance, and the
ray parameter is the nearer of the two crossings found by sampling the ray. Tolerances 1e-6 relative."""

import numpy as np
import pytest

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import DatasetSpec
from tpnet_gpu.scenes import Scene, random_scene, render
from tpnet_gpu.scenes.curved import Cylinder, Sphere, curved
from tpnet_gpu.scenes.objects import Patch

RIG = Rig(width=160, height=120)
TEXTURE = np.random.default_rng(0).uniform(0.2, 0.8, (64, 64, 3)).astype(np.float32)


def _scene(obj):
    return Scene([obj])


def _rays():
    y, x = np.mgrid[0:RIG.height:3, 0:RIG.width:3].astype(np.float64) + 0.5
    dirs = RIG.virtual_rays(np.stack([x, y], axis=-1).reshape(-1, 2))
    return np.zeros_like(dirs), dirs


def _first_crossing(inside, origins, dirs, t_max):
    """The ray parameter where ``inside(points)`` first turns true, by dense sampling then bisection."""
    ts = np.linspace(0.0, t_max, 4001)
    out = np.full(len(dirs), np.inf)
    for i in range(len(dirs)):
        flags = inside(origins[i] + ts[:, None] * dirs[i])
        if not flags.any():
            continue
        k = int(np.argmax(flags))
        lo, hi = ts[k - 1], ts[k]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if inside(origins[i] + mid * dirs[i][None])[0] else (mid, hi)
        out[i] = hi
    return out


def test_sphere_hits_where_geometry_says_and_at_its_placed_distance():
    sphere = curved(RIG, 20.0, TEXTURE, centre_px=(90.0, 50.0), size_px=(60.0, 60.0), kind="sphere")
    assert isinstance(sphere, Sphere)
    origins, dirs = _rays()
    t, _, _ = sphere.intersect(origins, dirs)
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    along = unit @ sphere.centre
    miss_distance = np.linalg.norm(sphere.centre - along[:, None] * unit, axis=1)
    np.testing.assert_array_equal(np.isfinite(t), miss_distance < sphere.radius)
    hits = np.isfinite(t)
    assert 50 < hits.sum() < len(t) // 2
    points = origins[hits] + t[hits, None] * dirs[hits]
    np.testing.assert_allclose(np.linalg.norm(points - sphere.centre, axis=1), sphere.radius, rtol=1e-6)
    sample = np.flatnonzero(hits)[::7]
    crossing = _first_crossing(lambda p: np.linalg.norm(p - sphere.centre, axis=1) <= sphere.radius,
                               origins[sample], dirs[sample], 2.0 * t[sample].max())
    np.testing.assert_allclose(t[sample], crossing, rtol=1e-6)
    # the nearest point is seen at the placed pixel and distance: the rendered disparity there is the plane's
    rendered = render(_scene(sphere), RIG, supersample=1, seed=0)
    assert rendered.disparity[50, 90] == pytest.approx(RIG.disparity(20.0), rel=1e-4)
    assert rendered.disparity[50, 90] >= np.nanmax(np.where(rendered.objects == 0, rendered.disparity, -np.inf)) - 1e-3


def test_cylinder_hits_its_side_within_its_height():
    cylinder = curved(RIG, 30.0, TEXTURE, centre_px=(70.0, 60.0), size_px=(40.0, 50.0), kind="cylinder")
    assert isinstance(cylinder, Cylinder)
    origins, dirs = _rays()
    t, _, v = cylinder.intersect(origins, dirs)
    hits = np.isfinite(t)
    assert 30 < hits.sum() < len(t) // 2
    rel = origins[hits] + t[hits, None] * dirs[hits] - cylinder.centre
    np.testing.assert_allclose(np.hypot(rel[:, 0], rel[:, 2]), cylinder.radius, rtol=1e-6)
    assert np.all(np.abs(rel[:, 1]) <= cylinder.half_height * (1 + 1e-9))
    np.testing.assert_allclose(v[hits], rel[:, 1])

    def inside(p):
        r = p - cylinder.centre
        return (np.hypot(r[:, 0], r[:, 2]) <= cylinder.radius) & (np.abs(r[:, 1]) <= cylinder.half_height)

    sample = np.flatnonzero(hits)[::5]
    np.testing.assert_allclose(t[sample], _first_crossing(inside, origins[sample], dirs[sample],
                                                          2.0 * t[sample].max()), rtol=1e-6)


def test_curved_disparity_bends_inside_the_outline():
    """A sphere's rendered disparity falls from its front point toward its outline (a plane's would not)."""
    sphere = curved(RIG, 10.0, TEXTURE, centre_px=(80.0, 60.0), size_px=(100.0, 100.0))
    d = render(_scene(sphere), RIG, supersample=1, seed=0).disparity
    row = d[60, 40:121]
    front = RIG.disparity(10.0)
    assert row.max() == pytest.approx(front, rel=1e-3)
    # 40 px off the front of a 50 px radius the surface lies R (1 - sqrt(1 - 0.8^2)) deeper (perspective aside)
    deeper = sphere.radius * (1.0 - np.sqrt(1.0 - 0.8 ** 2))
    expected = front * 10000.0 / (10000.0 + deeper)
    assert row[0] == pytest.approx(expected, rel=2e-3) and row[-1] == pytest.approx(expected, rel=2e-3)
    assert row[0] < front * 0.995


def test_random_scene_draws_curved_objects_only_when_asked():
    planar = random_scene(RIG, np.random.default_rng(4))
    assert all(isinstance(o, Patch) for o in planar.objects)
    again = random_scene(RIG, np.random.default_rng(4), curved=0.0)
    assert [o.name for o in again.objects] == [o.name for o in planar.objects]
    np.testing.assert_array_equal(np.stack([o.origin for o in again.objects]),
                                  np.stack([o.origin for o in planar.objects]))
    bent = random_scene(RIG, np.random.default_rng(4), curved=1.0)
    movable = [o for o in bent.objects if o.name != "background"]
    assert movable and all(isinstance(o, Sphere) for o in movable)


def test_bad_curved_input_is_refused():
    with pytest.raises(ValueError, match="kind"):
        curved(RIG, 10.0, TEXTURE, centre_px=(80.0, 60.0), size_px=(10.0, 10.0), kind="cone")
    with pytest.raises(ValueError, match="curved"):
        DatasetSpec(curved=1.5)
