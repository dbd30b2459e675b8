"""Robust Levenberg-Marquardt fit of the extrinsic corrections to measured pair peaks (docs/calibration.md §3).

Unknowns: the corrections' observable coordinates p ``(k,)`` (``model.observable_basis``) and one disparity
correction per tile ``(T,)``. Residuals: measured minus modelled 2-D lags, ``(T, P, 2)``. Cauchy weights per
tile and pair, w = 1 / (1 + |r|^2 / c^2) (iteratively re-weighted: gross tiles - a wrong disparity, two depths in
a window - get little say). The per-tile unknowns are eliminated from the normal equations by their Schur
complement, so a step costs one k x k solve whatever the number of tiles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpnet_gpu.calibration import model


@dataclass(frozen=True)
class Observations:
    """Measured peaks of ``T`` tiles of one or more frames.

    Attributes:
        centre: ``(T, 2)`` virtual-camera tile centres, px.
        disparity: ``(T,)`` target disparities the tiles were correlated at, px.
        lags: ``(T, P, 2)`` measured 2-D peak lags (x, y), px; NaN where a pair has none.
        reference: ``(T, P, 2)`` pair differences of the centres they were correlated at (P_b^0 - P_a^0), px.
    """

    centre: np.ndarray
    disparity: np.ndarray
    lags: np.ndarray
    reference: np.ndarray

    @staticmethod
    def join(parts) -> Observations:
        parts = list(parts)
        return Observations(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                              ("centre", "disparity", "lags", "reference")))


@dataclass(frozen=True)
class LmaSettings:
    """``cauchy_px``: the Cauchy scale c; ``iterations``: most LM steps; ``tolerance``: stop when the largest
    step of the corrections moves the frame edge by less than this (px); ``damping``: the initial lambda."""

    cauchy_px: float = 0.25
    iterations: int = 30
    tolerance: float = 1e-4
    damping: float = 1e-3


def _residuals(rig, e, obs: Observations, delta, pairs):
    p = model.ports(rig, e, obs.centre, obs.disparity + delta)
    return obs.lags - (model.pair_differences(p, pairs) - obs.reference)


def _cost(r: np.ndarray, c: float) -> float:
    sq = np.nansum(r**2, axis=-1)
    return float(np.sum(np.where(np.isfinite(r[..., 0]), 0.5 * c * c * np.log1p(sq / (c * c)), 0.0)))


def fit(rig, start, obs: Observations, pairs, settings: LmaSettings = LmaSettings()) -> tuple[np.ndarray, dict]:
    """Corrections ``(13,)`` that best explain ``obs`` from ``start`` (gauge components of ``start`` kept) and a
    summary: ``iterations``, ``cost`` (start, end), ``rms_inliers`` (px, residuals below 3 c), ``inliers``."""
    basis = model.observable_basis(rig)
    c = settings.cauchy_px
    e = np.asarray(start, dtype=np.float64).copy()
    delta = np.zeros(len(obs.disparity))
    r = _residuals(rig, e, obs, delta, pairs)
    cost0 = cost = _cost(r, c)
    lam = settings.damping
    edge = float(np.max(np.abs([rig.width, rig.height]))) / 2 + rig.focal_px  # px moved per radian, at most
    it = 0
    for it in range(1, settings.iterations + 1):
        _, j_e, j_d = model.jacobians(rig, e, obs.centre, obs.disparity + delta, basis)
        a_e = model.pair_differences(j_e, pairs)  # (T, P, 2, k)
        a_d = model.pair_differences(j_d, pairs)  # (T, P, 2)
        finite = np.isfinite(r[..., 0])
        w = np.where(finite, 1.0 / (1.0 + np.nansum(r**2, axis=-1) / (c * c)), 0.0)[..., None]  # (T, P, 1)
        rr = np.nan_to_num(r)
        big_a = np.einsum("tpik,tpi,tpil->kl", a_e, np.broadcast_to(w, rr.shape), a_e)
        b = np.einsum("tpik,tpi,tpi->tk", a_e, np.broadcast_to(w, rr.shape), a_d)  # (T, k)
        cc = np.einsum("tpi,tpi->t", w * a_d, a_d)
        g_e = np.einsum("tpik,tpi->k", a_e, w * rr)
        g_d = np.einsum("tpi,tpi->t", w * a_d, rr)
        while True:
            c_damped = cc * (1 + lam) + 1e-12
            schur = big_a + lam * np.diag(np.diag(big_a)) - np.einsum("tk,tl->kl", b / c_damped[:, None], b)
            step = np.linalg.solve(schur, g_e - (b / c_damped[:, None]).T @ g_d)
            d_step = (g_d - b @ step) / c_damped
            e_new = e + basis @ step
            r_new = _residuals(rig, e_new, obs, delta + d_step, pairs)
            cost_new = _cost(r_new, c)
            if cost_new <= cost:
                e, delta, r, cost = e_new, delta + d_step, r_new, cost_new
                lam = max(lam / 10, 1e-9)
                break
            lam *= 10
            if lam > 1e8:
                break
        if lam > 1e8 or np.max(np.abs(step)) * edge < settings.tolerance:
            break
    norm = np.linalg.norm(r, axis=-1)
    inliers = np.isfinite(norm) & (norm < 3 * c)
    return e, {"iterations": it, "cost": (cost0, cost), "inliers": int(inliers.sum()),
               "rms_inliers": float(np.sqrt(np.mean(norm[inliers] ** 2))) if inliers.any() else float("nan")}
