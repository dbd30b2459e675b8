"""Simple sub-pixel peak estimators for the correlation tests (the tile processor's own fit is the LMA of a
later stage). Both return the peak position (m_x, m_y) in lags from the tile centre."""

from __future__ import annotations

import numpy as np


def parabola_peak(corr: np.ndarray) -> np.ndarray:
    """Integer argmax refined by a 3-point parabola per axis (argmax kept one cell inside the border)."""
    r = corr.shape[-1] // 2
    iy, ix = np.unravel_index(np.argmax(corr), corr.shape)
    iy, ix = np.clip(iy, 1, corr.shape[0] - 2), np.clip(ix, 1, corr.shape[1] - 2)

    def vertex(m1, m0, p1):
        den = m1 - 2 * m0 + p1
        return 0.0 if den == 0 else 0.5 * (m1 - p1) / den

    dx = vertex(corr[iy, ix - 1], corr[iy, ix], corr[iy, ix + 1])
    dy = vertex(corr[iy - 1, ix], corr[iy, ix], corr[iy + 1, ix])
    return np.array([ix - r + dx, iy - r + dy])


def centroid_peak(corr: np.ndarray, half: int = 2) -> np.ndarray:
    """Centre of mass of the positive part of the (2 half + 1)^2 cells around the integer argmax."""
    r = corr.shape[-1] // 2
    iy, ix = np.unravel_index(np.argmax(corr), corr.shape)
    iy = np.clip(iy, half, corr.shape[0] - 1 - half)
    ix = np.clip(ix, half, corr.shape[1] - 1 - half)
    win = np.maximum(corr[iy - half : iy + half + 1, ix - half : ix + half + 1], 0.0)
    lags = np.arange(-half, half + 1)
    return np.array([ix - r + win.sum(0) @ lags / win.sum(), iy - r + win.sum(1) @ lags / win.sum()])
