"""Evaluation metrics (tpnet_gpu/evaluation.py) on hand-made grids."""

import numpy as np

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
