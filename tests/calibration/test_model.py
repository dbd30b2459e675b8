"""Calibration geometry (tpnet_gpu/calibration/model.py). Oracles: ``Rig.port_coordinates`` (the rig model, not
the Jacobians under test) and linear algebra: the gauge directions do not change the pair differences at infinity
(common roll exactly; toe-in up to second order, and it equals a disparity offset); the Schur-reduced design has
exactly 11 well-conditioned directions; the synthetic misalignment moves the edge by what it says.
Break tried: the toe-in's tilt sign flipped (the toe-in test fails by ~1 px)."""

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.calibration import model
from tpnet_gpu.calibration.measure import tile_grid_centres
from tpnet_gpu.calibration.synthetic import misalignment
from tpnet_gpu.camera import Rig

RIG = Rig(width=320, height=240)


def _pair_diff(e, centre, d):
    return model.pair_differences(model.ports(RIG, e, centre, d), tables.QUAD_PAIRS)


def test_gauge_directions_are_unobservable():
    centre = tile_grid_centres(RIG)
    zero = np.zeros(len(centre))
    g = model.gauge(RIG)
    base = _pair_diff(np.zeros(13), centre, zero)
    roll = g[:, 0] * 1e-3 / np.abs(g[:, 0]).max()
    assert np.max(np.abs(_pair_diff(roll, centre, zero) - base)) < 1e-9
    toe = g[:, 1] * 2.0 / RIG.focal_px / np.abs(g[:, 1]).max()  # ~1 px per camera
    # a toe-in equals a disparity offset: every pair moves by -delta (r_b - r_a), up to second-order terms
    moved = _pair_diff(toe, centre, zero)
    per_px = _pair_diff(np.zeros(13), centre, zero + 1.0) - base  # one pixel of disparity
    delta = np.linalg.lstsq(per_px.reshape(-1, 1), (moved - base).reshape(-1), rcond=None)[0]
    fitted = base + delta * per_px
    assert abs(delta[0]) > 0.5 and np.max(np.abs(moved - fitted)) < 0.015 * abs(delta[0])  # 4 px: 0.034 px left


def test_observable_design_rank():
    centre = tile_grid_centres(RIG)
    d = np.random.default_rng(0).uniform(0, 20, len(centre))
    _, j_e, j_d = model.jacobians(RIG, np.zeros(13), centre, d, np.eye(13))
    a = model.pair_differences(j_e, tables.QUAD_PAIRS).reshape(len(centre), -1, 13)
    b = model.pair_differences(j_d, tables.QUAD_PAIRS).reshape(len(centre), -1, 1)
    # remove each tile's disparity column (the Schur complement), then the singular values of the rest
    proj = a - b * (np.einsum("tpi,tpk->tik", b, a) / np.einsum("tpi,tpi->ti", b, b)[..., None])
    s = np.linalg.svd(proj.reshape(-1, 13), compute_uv=False)
    # 11 observable (the weakest, a zoom, 1.8e-2 of the strongest); the gauge: ~1e-3 (the toe-in's second-order
    # terms, the common roll times the disparity)
    assert s[10] / s[0] > 1e-2 and s[11] / s[0] < 2e-3
    basis = model.observable_basis(RIG)
    assert np.allclose(basis.T @ basis, np.eye(11)) and np.allclose(model.gauge(RIG).T @ basis, 0)


def test_synthetic_misalignment_size():
    for level in (0.4, 2.5):
        e = misalignment(RIG, level, seed=3)
        assert abs(model.edge_misalignment(RIG, e, np.zeros(13)) - level) < 0.01 * level
        assert np.allclose(model.gauge(RIG).T @ e, 0)
