"""The calibration's geometry (docs/calibration.md §1, §3): what a pair's 2-D peak says about the rig's
extrinsic corrections, their Jacobians (central differences of ``Rig.port_coordinates``: no second copy of the
rig model), the unobservable directions (gauge) and the frame-edge misalignment between two rigs.

A tile correlated at centres P_i^0 (rig e0, target disparity d) whose point truly lies at P_i(e, D) shows, for
pair a -> b, its peak at lag m = (P_b(e, D) - P_a(e, D)) - (P_b^0 - P_a^0) (the processor's sign convention).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tpnet_gpu.camera import EXTRINSIC_TERMS, Rig

STEP = 1e-6  # rad (and per-mille of zoom): F * STEP ~ 0.002 px, far inside the model's linear range
TILT, AZIMUTH, ROLL = slice(0, 3), slice(3, 6), slice(6, 10)


def with_extrinsics(rig: Rig, extrinsics) -> Rig:
    """``rig`` with other extrinsic corrections (a fresh model cache)."""
    return replace(rig, extrinsics=tuple(float(v) for v in extrinsics), _cache={})


def check_quad(rig: Rig) -> None:
    if rig.cams != 4:
        raise ValueError(f"rig: calibration fits the quad's 13 extrinsic terms and needs 4 cameras, got {rig.cams}")


def gauge(rig: Rig) -> np.ndarray:
    """``(13, 2)`` orthonormal directions the pair peaks cannot see: the common roll (every image turned about its
    centre: pair lags change only by d times the turn, nil at infinity) and the toe-in (azimuth_i ~ r_ix, tilt_i ~
    -r_iy: each camera moves by a multiple of its offset, exactly what a disparity offset does)."""
    check_quad(rig)
    r = rig.offsets_array() - rig.offsets_array().mean(axis=0)  # the fourth camera's terms are minus the sums
    roll = np.zeros(EXTRINSIC_TERMS)
    roll[ROLL] = 1.0
    toe = np.zeros(EXTRINSIC_TERMS)
    toe[AZIMUTH], toe[TILT] = r[:3, 0], -r[:3, 1]
    q, _ = np.linalg.qr(np.stack([roll, toe], axis=1))
    return q


def observable_basis(rig: Rig) -> np.ndarray:
    """``(13, 11)`` orthonormal basis of the directions orthogonal to :func:`gauge`: the fitted subspace."""
    g = gauge(rig)
    u, _, _ = np.linalg.svd(np.eye(EXTRINSIC_TERMS) - g @ g.T)
    return u[:, : EXTRINSIC_TERMS - g.shape[1]]


def observable_part(rig: Rig, extrinsics) -> np.ndarray:
    """``extrinsics (13,)`` without their gauge components."""
    g = gauge(rig)
    e = np.asarray(extrinsics, dtype=np.float64)
    return e - g @ (g.T @ e)


def ports(rig: Rig, extrinsics, centre: np.ndarray, disparity: np.ndarray) -> np.ndarray:
    """``(T, cams, 2)`` port coordinates of virtual-camera points ``centre (T, 2)`` at ``disparity (T,)``."""
    return with_extrinsics(rig, extrinsics).port_coordinates(centre, disparity)


def pair_differences(x: np.ndarray, pairs) -> np.ndarray:
    """``(T, P, ...)``: x[:, b] - x[:, a] for each pair (a, b) of per-camera values ``x (T, cams, ...)``."""
    return np.stack([x[:, b] - x[:, a] for a, b in pairs], axis=1)


def jacobians(rig: Rig, extrinsics, centre, disparity, basis: np.ndarray):
    """Ports ``(T, cams, 2)`` and their derivatives along ``basis (13, k)`` ``(T, cams, 2, k)`` and along the
    disparity ``(T, cams, 2)`` (central differences)."""
    e = np.asarray(extrinsics, dtype=np.float64)
    p = ports(rig, e, centre, disparity)
    j_e = np.stack([(ports(rig, e + STEP * b, centre, disparity) - ports(rig, e - STEP * b, centre, disparity))
                    / (2 * STEP) for b in basis.T], axis=-1)
    j_d = (ports(rig, e, centre, disparity + 1e-4) - ports(rig, e, centre, disparity - 1e-4)) / 2e-4
    return p, j_e, j_d


def edge_points(rig: Rig, per_side: int = 9) -> np.ndarray:
    """``(M, 2)`` virtual-camera points along the frame's border (the corners included)."""
    xs = np.linspace(0.0, rig.width, per_side)
    ys = np.linspace(0.0, rig.height, per_side)
    return np.concatenate([np.stack([xs, np.zeros_like(xs)], 1), np.stack([xs, np.full_like(xs, rig.height)], 1),
                           np.stack([np.zeros_like(ys), ys], 1), np.stack([np.full_like(ys, rig.width), ys], 1)])


def edge_misalignment(rig: Rig, extrinsics, truth) -> float:
    """Largest displacement (px) over the frame's border and the cameras, at infinity, between the images of
    ``extrinsics`` and ``truth`` (both without their gauge components: calibration cannot tell those apart)."""
    points = edge_points(rig)
    zero = np.zeros(len(points))
    a = ports(rig, observable_part(rig, extrinsics), points, zero)
    b = ports(rig, observable_part(rig, truth), points, zero)
    return float(np.max(np.linalg.norm(a - b, axis=-1)))
