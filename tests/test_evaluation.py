"""Evaluation metrics (tpnet_gpu/evaluation.py) on hand-made grids."""

import numpy as np
import pytest

from tpnet_gpu import evaluation


def test_classes_and_stats():
    gt = np.zeros((6, 6))
    gt[:, 3:] = 5.0  # a depth edge between columns 2 and 3
    conf = np.ones((6, 6))
    conf[1, 1] = 0.0
    spread = np.zeros((6, 6))
    cls = evaluation.tile_classes(gt, conf, spread)
    assert cls["edge"][1:-1, 2:4].all() and not cls["edge"][:, 0].any()
    assert cls["low_texture"][1, 1] and not cls["flat"][1, 1] and cls["flat"][2, 1]
    assert not cls["all"][0].any()
    est = gt.copy()
    est[2, 1] = 0.5
    est[3, 1] = 3.0  # a gross error
    est[4, 1] = np.nan
    stats = evaluation.error_stats(est, gt, cls["flat"])
    # flat: column 1 rows 2-4 and column 4 rows 1-4 (column 2 and 3 see the edge, (1, 1) has no texture)
    assert stats["tiles"] == 7 and np.isclose(stats["coverage"], 6 / 7)
    assert np.isclose(stats["right"], 5 / 7)  # the NaN and the gross tile are not right
    assert np.isclose(stats["rmse"], np.sqrt((0.25 + 9.0) / 6)) and np.isclose(stats["gross"], 1 / 6)
    assert np.isclose(stats["rmse_inliers"], np.sqrt(0.25 / 5))
    bins = evaluation.rmse_by_spread(est, gt, cls["all"])
    assert sum(b["tiles"] for b in bins) == cls["all"].sum()


def test_reference_inliers_and_common_rmse():
    # oracle: hand-counted tiles; the common set is chosen by the reference alone
    gt = np.zeros((2, 3))
    ref = np.array([[0.1, 2.0, np.nan], [0.0, -0.5, 0.2]])
    common = evaluation.reference_inliers(ref, gt)
    np.testing.assert_array_equal(common, [[True, False, False], [True, True, True]])
    est = np.array([[0.3, 0.0, 0.0], [0.0, 0.4, 5.0]])
    stats = evaluation.error_stats(est, gt, np.ones((2, 3), bool), common)
    assert np.isclose(stats["rmse_common"], np.sqrt((0.09 + 0.16 + 25.0) / 4))  # the gross 5.0 stays in
    assert "rmse_common" not in evaluation.error_stats(est, gt, np.ones((2, 3), bool))
    est[1, 2] = np.nan  # a tile the method misses is left out of its common RMSE (coverage counts it)
    stats = evaluation.error_stats(est, gt, np.ones((2, 3), bool), common)
    assert np.isclose(stats["rmse_common"], np.sqrt((0.09 + 0.16) / 3)) and np.isclose(stats["coverage"], 5 / 6)


def _surfaces(*rows_per_tile):
    """Hand-made ``tile_surfaces`` of one row of tiles: per tile its (share, min, max) rows, NaN-padded to 2."""
    out = np.full((1, len(rows_per_tile), 2, 3), np.nan)
    for i, rows in enumerate(rows_per_tile):
        out[0, i, : len(rows)] = rows
    return out


def test_either_surface_and_strict_gross():
    # oracle: hand-checked per tile against the definition (module docstring)
    gt = np.array([[5.0, 3.0, 3.0, 5.0, 1.0, 9.0]])
    surfaces = _surfaces([(0.6, 5.0, 5.0), (0.4, 0.0, 0.0)],  # a depth edge: the far side is right too
                         [(1.0, 2.0, 4.0)],  # one slanted plane spanning 2..4 px over the window
                         [(1.0, 2.0, 4.0)],
                         [(0.95, 5.0, 5.0), (0.05, 0.0, 0.0)],  # 5 % of the window: too small to count
                         [(1.0, 1.0, 1.0)],
                         [(0.97, 2.0, 2.0), (0.03, 9.0, 9.0)])  # a thin object under the centre ray
    est = np.array([[0.3, 5.0, 5.1, 0.0, np.nan, 9.2]])
    ok = evaluation.either_surface_correct(est, gt, surfaces)
    np.testing.assert_array_equal(ok, [[True, True, False, False, False, True]])
    np.testing.assert_array_equal(evaluation.is_gross(est, gt), [[True, True, True, True, False, False]])
    stats = evaluation.error_stats(est, gt, np.ones(gt.shape, bool), surfaces=surfaces)
    assert np.isclose(stats["gross"], 4 / 5) and np.isclose(stats["gross_either"], 2 / 5)
    assert np.isclose(stats["coverage"], 5 / 6) and np.isclose(stats["rmse_inliers"], 0.2)
    assert "gross_either" not in evaluation.error_stats(est, gt, np.ones(gt.shape, bool))
    assert np.isnan(evaluation.error_stats(est, gt, np.zeros(gt.shape, bool), surfaces=surfaces)["gross_either"])


def test_new_gross_against_a_reference():
    # oracle: hand-counted: the reference is right at (0,0), (1,0), (1,1), (1,2); the method breaks (0,0) and
    # (1,2), misses (1,0) (not gross: coverage counts it) and is gross at (0,1) where the reference was too
    gt = np.zeros((2, 3))
    ref = np.array([[0.1, 2.0, np.nan], [0.0, -0.5, 0.2]])
    est = np.array([[3.0, 5.0, 5.0], [np.nan, 0.4, -1.5]])
    assert evaluation.new_gross(est, ref, gt) == {"count": 2, "share": 0.5, "reference_right": 4}
    mask = np.array([[False, True, True], [True, True, True]])
    assert evaluation.new_gross(est, ref, gt, mask) == {"count": 1, "share": 1 / 3, "reference_right": 3}
    assert evaluation.new_gross(ref, ref, gt)["count"] == 0
    stats = evaluation.error_stats(est, gt, mask, evaluation.reference_inliers(ref, gt))
    assert stats["new_gross"] == 1 and np.isclose(stats["new_gross_share"], 1 / 3)
    assert np.isnan(evaluation.new_gross(est, ref, gt, np.zeros((2, 3), bool))["share"])


def test_confidence_ranking():
    # oracle: hand-sorted: finite tiles 0, 1, 2, 4 by confidence are 0 (0.9), 2 (0.8), 1 (0.1), 4 (NaN: last);
    # 90 % of 4 keeps 4 tiles (gross: 1 and 4), 75 % keeps 3 (gross: 1), 25 % keeps 1
    gt = np.zeros((1, 5))
    est = np.array([[0.1, 3.0, 0.2, np.nan, 2.0]])
    conf = np.array([[0.9, 0.1, 0.8, 1.0, np.nan]])
    mask = np.ones((1, 5), bool)
    rows = evaluation.confidence_ranking(est, conf, gt, mask)
    assert [(r["fraction"], r["tiles"]) for r in rows] == [(0.9, 4), (0.75, 3)]
    assert np.isclose(rows[0]["gross"], 2 / 4) and np.isclose(rows[1]["gross"], 1 / 3) and "gross_either" not in rows[0]
    # tile 1 at 3.0 is on the window's other surface: either-surface right
    surfaces = _surfaces(*[[(1.0, 0.0, 0.0)]] * 5)
    surfaces[0, 1, 1] = (0.3, 2.5, 2.5)
    rows = evaluation.confidence_ranking(est, conf, gt, mask, (0.9, 0.75, 0.25), surfaces=surfaces)
    assert [r["gross_either"] for r in rows] == [1 / 4, 0.0, 0.0] and rows[2]["tiles"] == 1
    assert evaluation.confidence_ranking(est, None, gt, mask) is None
    assert np.isnan(evaluation.confidence_ranking(est, conf, gt, np.zeros((1, 5), bool))[0]["gross"])


def test_rendered_board_edge_has_two_surfaces():
    """A board at 60 m in front of a textured plane at 400 m (the renderer): a tile on the board's edge sees
    both; oracle: the distances they were placed at (d = f B / (Z p)); an estimate at either disparity is
    either-surface right, only the centre ray's is strictly right."""
    from tpnet_gpu.camera import Rig
    from tpnet_gpu.scenes import Scene, Sky, plane, render
    from tpnet_gpu.scenes import textures as tx

    rig = Rig(width=96, height=64)
    rng = np.random.default_rng(0)
    board = plane(rig, 60.0, tx.noise_texture(rng, 128), centre_px=(32, 32), size_px=(32, 80))  # x 16..48
    back = plane(rig, 400.0, tx.noise_texture(rng, 128))
    out = render(Scene([board, back], Sky()), rig, supersample=1, noise=False)
    near, far = rig.disparity(60.0), rig.disparity(400.0)
    ty, tx_ = 4, 6  # centre (52, 36): the far plane; window x 44..60: 4 columns of board, 12 of the far plane
    surfaces = out.tile_surfaces[ty, tx_]
    np.testing.assert_allclose(surfaces[:2, 0], [0.75, 0.25])
    np.testing.assert_allclose(surfaces[:2, 1:], [[far, far], [near, near]], rtol=1e-5)
    assert np.isnan(surfaces[2:]).all() and out.tile_disparity[ty, tx_] == pytest.approx(far, rel=1e-5)
    gt = out.tile_disparity[ty, tx_]
    for estimate in (far + 0.9, near - 0.9):
        assert evaluation.either_surface_correct(np.array(estimate), gt, surfaces)
    assert not evaluation.is_gross(np.array(far + 0.9), gt) and evaluation.is_gross(np.array(near - 0.9), gt)
    assert not evaluation.either_surface_correct(np.array((near + far) / 2), gt, surfaces)
    assert not evaluation.either_surface_correct(np.array(near + 1.1), gt, surfaces)
