"""Calibration by gradient descent through the differentiable tile processor (docs/calibration.md §4).

Per round: the tiles and their disparities come from the same 2-D peak sweep as the LMA's
(``measure.tile_disparities``); the per-camera tile centres are linearised in the corrections' observable
coordinates p ``(k,)`` and per-tile disparity corrections ``(T,)`` (``model.jacobians``, exact first
derivatives of ``Rig.port_coordinates``); then L-BFGS moves (p, delta) to minimise the Cauchy loss of the pair
peaks' lags, every step re-correlating the frames at the moved centres through ``tpnet_gpu.differentiable`` and
back-propagating through the peak locator, the correlation and the MCLT to the centres.
"""

from __future__ import annotations

import numpy as np
import torch

from tpnet_gpu import tables
from tpnet_gpu.calibration import model
from tpnet_gpu.calibration.measure import engine_for, tile_disparities, tile_grid_centres
from tpnet_gpu.calibration.peaks import pair_peaks
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.differentiable import bayer_planes, correlate
from tpnet_gpu.disparity.engine import correlation_for

CAUCHY_PX = 0.5  # wider than the LMA's: the loss must still pull the first round's lags of several px


def _green_only(config: CorrelationConfig) -> bool:
    return config.colour_weights is not None and tuple(config.colour_weights[:2]) == (0.0, 0.0)


def _frame_problem(frame, rig, basis, max_tiles, device, backend):
    """One frame's planes ``(cams, C, H, W)``, the correlation settings, and its (at most ``max_tiles``
    strongest) tiles' linearised centres: ``(planes, config, p0 (T, cams, 2), j_e (T, cams, 2, k),
    j_d (T, cams, 2))`` (float32 torch: each step re-correlates every tile, float64 would double its cost)."""
    engine = engine_for(frame, rig, device, backend)
    disparity, _, strength = tile_disparities(engine, rig)
    index = torch.nonzero(strength >= engine.config.min_strength)[:, 0]
    index = index[torch.argsort(strength[index], descending=True)[:max_tiles]].numpy()
    centre = tile_grid_centres(rig)[index]
    p0, j_e, j_d = model.jacobians(rig, rig.extrinsics, centre, disparity.numpy()[index], basis)
    mosaics = engine.tp.staging.detach().to(torch.float32).clone()  # the engine's scaled frames
    config = correlation_for(frame.cfa)
    if frame.cfa is None:
        planes, config = mosaics[:, None], config.resolved(1)
    else:
        planes = bayer_planes(mosaics, frame.cfa)
        config = config.resolved(3)
        if _green_only(config):  # the red and blue products are weighted 0: correlate green alone, the same sums
            planes = planes[:, 2:3]
            config = CorrelationConfig((1.0,), config.fat_zero, config.sigma_rb, config.sigma_corr).resolved(1)
    as_t = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    return planes, config, as_t(p0), as_t(j_e), as_t(j_d)


def fit(frames, rig, steps: int, max_tiles: int, *, device=None, backend=None, cauchy_px: float = CAUCHY_PX):
    """One round: the corrections ``(13,)`` after ``steps`` L-BFGS iterations from ``rig``'s (at most
    ``max_tiles`` tiles per frame), and a summary (``tiles``, ``loss`` start/end, ``evaluations``)."""
    basis = model.observable_basis(rig)
    problems = [_frame_problem(f, rig, basis, max_tiles, device, backend) for f in frames]
    p = torch.zeros(basis.shape[1], dtype=torch.float32, requires_grad=True)
    deltas = [torch.zeros(len(pr[2]), dtype=torch.float32, requires_grad=True) for pr in problems]
    scale = float(rig.focal_px)  # p in px-sized units: the optimiser sees comparable scales
    c2 = cauchy_px**2
    evaluations = []

    def loss_fn():
        total = 0.0
        for (planes, config, p0, j_e, j_d), delta in zip(problems, deltas):
            centres = p0 + j_e @ (p / scale) + j_d * delta[:, None, None]  # (T, cams, 2)
            corr, _ = correlate(planes, centres, tables.QUAD_PAIRS, config)
            lags, _ = pair_peaks(corr)
            sq = (lags**2).sum(dim=-1)
            total = total + torch.where(torch.isfinite(sq), 0.5 * c2 * torch.log1p(sq / c2),
                                        torch.zeros_like(sq)).sum()
        return total

    optimiser = torch.optim.LBFGS([p, *deltas], max_iter=steps, line_search_fn="strong_wolfe")

    def closure():
        optimiser.zero_grad()
        loss = loss_fn()
        loss.backward()
        evaluations.append(float(loss.detach()))
        return loss

    optimiser.step(closure)
    e = np.asarray(rig.extrinsics, dtype=np.float64) + basis @ (p.detach().double().numpy() / scale)
    return e, {"tiles": sum(len(pr[2]) for pr in problems), "loss": (evaluations[0], evaluations[-1]),
               "evaluations": len(evaluations)}
