"""Hand-crafted baseline, first half: pair correlations -> disparity "strips" -> their combination -> integer
maximum and windowed centre of mass (geometry_and_lma.md B.3, C.1-C.3). NumPy, vectorised over tiles.

Units: lags in pixels; a strip column s (-7..7) is a position along the pair's disparity axis in disparity
units (the adjacent-pair shift), so a residual disparity delta puts every strip's peak at s = -delta.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpnet_gpu import tables

RADIUS = tables.CORR_RADIUS
STRIP_ROWS = 9  # corr_strip_hight
STRIP_COLS = 2 * RADIUS + 1
# Pair directions u (first -> second camera) in lag units, quad order (geometry B.1).
PAIR_AXES = ((1, 0), (1, 0), (0, 1), (0, 1), (1, 1), (1, -1))


@dataclass(frozen=True)
class StripParams:
    """C.7 defaults. ``corr_offset`` >= 0: geometric mean of (strip + offset) over pairs; < 0: plain mean."""

    corr_offset: float = 0.1
    min_corr: float = 0.02
    min_poly_strength: float = 0.2


def half_flat_top(size: int, hwidth: float, blur: float, scale: float = 1.0) -> np.ndarray:
    """C.2 window half: 1 to hwidth - blur/2, 0 past hwidth + blur/2, (1 - sin(pi (i - hwidth) / blur)) / 2
    between; normalised so w[0] + 2 sum w[1:] = 1, times ``scale``."""
    i = np.arange(size, dtype=np.float64)
    w = np.where(i <= hwidth - blur / 2, 1.0, np.where(i >= hwidth + blur / 2, 0.0,
                 0.5 * (1.0 - np.sin(np.pi * (i - hwidth) / blur))))
    return scale * w / (w[0] + 2.0 * w[1:].sum())


WINDOW_Y = half_flat_top(2, 1.0, 1.0)  # [0.5, 0.25]
WINDOW_X = half_flat_top(9, 6.0, 5.0, 2.0)  # half-disparity steps 0..8


def _bilinear(corr: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sample ``corr (T, 15, 15)`` at lag positions x, y (same shape S); NaN outside +-7. -> (T, *S)."""
    inside = (np.abs(x) <= RADIUS) & (np.abs(y) <= RADIUS)
    cx = np.clip(x + RADIUS, 0, 2 * RADIUS)
    cy = np.clip(y + RADIUS, 0, 2 * RADIUS)
    x0 = np.minimum(np.floor(cx).astype(int), 2 * RADIUS - 1)
    y0 = np.minimum(np.floor(cy).astype(int), 2 * RADIUS - 1)
    fx, fy = cx - x0, cy - y0
    v = (corr[:, y0, x0] * (1 - fx) * (1 - fy) + corr[:, y0, x0 + 1] * fx * (1 - fy)
         + corr[:, y0 + 1, x0] * (1 - fx) * fy + corr[:, y0 + 1, x0 + 1] * fx * fy)
    return np.where(inside, v, np.nan)


def _strip_positions(pair: int) -> tuple[np.ndarray, np.ndarray]:
    """Lag positions ``(2, 9, 15)`` x and y of the two points (both sides of the axis) of every strip cell."""
    s = np.arange(-RADIUS, RADIUS + 1)[None, :].astype(np.float64)
    r = np.arange(STRIP_ROWS)[:, None].astype(np.float64)
    odd = (np.arange(STRIP_ROWS)[:, None] % 2) / 2.0
    ux, uy = PAIR_AXES[pair]
    xs, ys = [], []
    for sign in (1, -1):
        if uy == 0:  # horizontal
            x, y = s + odd + 0 * r, sign * r / 2 + 0 * s
        elif ux == 0:  # vertical
            x, y = sign * r / 2 + 0 * s, s + odd + 0 * r
        else:  # diagonal: integer checkerboard cells next to the diagonal
            x = s - np.floor(sign * r / 2)
            y = s + np.floor((sign * r + 1) / 2)
            if uy < 0:
                y = -y
        xs.append(x)
        ys.append(y)
    return np.stack(xs), np.stack(ys)


def pair_strips(corr: np.ndarray) -> np.ndarray:
    """Strips ``(T, 6, 9, 15)`` of pair correlations ``(T, 6, 15, 15)`` (B.3): row 0 the disparity axis,
    row r the mean of the two points r/2 disparity units off the axis (odd rows shifted half a step)."""
    corr = np.asarray(corr, dtype=np.float64)
    if corr.ndim != 4 or corr.shape[1:] != (6, STRIP_COLS, STRIP_COLS):
        raise ValueError(f"corr: expected shape (tiles, 6, 15, 15), got {corr.shape}")
    strips = []
    for pair in range(6):
        x, y = _strip_positions(pair)
        values = _bilinear(corr[:, pair], x, y)  # (T, 2, 9, 15)
        strips.append(values.mean(axis=1))
    return np.stack(strips, axis=1)


def combine_strips(strips: np.ndarray, offset: float = 0.1, pairs=None) -> np.ndarray:
    """Combine pair strips ``(T, 6, 9, 15)`` into ``(T, 9, 15)``: with offset o >= 0 the geometric mean of
    max(strip + o, 0) minus o (0 stays 0); o < 0 the arithmetic mean. ``pairs``: optional bool mask (6,)."""
    strips = np.asarray(strips, dtype=np.float64)
    if pairs is not None:
        strips = strips[:, np.asarray(pairs, dtype=bool)]
    if offset < 0:
        return np.mean(strips, axis=1)
    shifted = np.maximum(strips + offset, 0.0)
    with np.errstate(divide="ignore"):
        geo = np.exp(np.mean(np.log(shifted), axis=1))
    return np.where(geo > 0, geo - offset, 0.0)


@dataclass(frozen=True)
class CentreOfMass:
    """Per-tile result of C.1 steps 2-3: ``x_int`` integer argmax lag, ``x_cm`` refined lag (NaN where
    rejected), ``strength`` value at the argmax, ``weight`` sum of the CM weights; shapes ``(T,)``."""

    x_int: np.ndarray
    x_cm: np.ndarray
    strength: np.ndarray
    weight: np.ndarray

    @property
    def disparity(self) -> np.ndarray:
        """Residual disparity -x_cm (px)."""
        return -self.x_cm


def centre_of_mass(combo: np.ndarray, params: StripParams = StripParams()) -> CentreOfMass:
    """Integer maximum of row 0 and the windowed centre of mass over rows 0 and 1 (C.2, C.3), ``(T, 9, 15)``."""
    combo = np.asarray(combo, dtype=np.float64)
    row0 = np.where(np.isfinite(combo[:, 0]), combo[:, 0], -np.inf)
    ix = np.argmax(row0, axis=1)
    t = np.arange(len(combo))
    strength = row0[t, ix]
    num = np.zeros(len(combo))
    den = np.zeros(len(combo))
    for row, row_weight in ((0, WINDOW_Y[0]), (1, 2.0 * WINDOW_Y[1])):
        for h in range(-8, 9):
            if (h - row) % 2:
                continue
            col = ix + h // 2
            ok = (col >= 0) & (col < STRIP_COLS)
            v = combo[t, row, np.clip(col, 0, STRIP_COLS - 1)]
            use = ok & np.isfinite(v) & (v > 0)
            m = np.where(use, v, 0.0) * WINDOW_X[abs(h)] * row_weight
            num += m * h
            den += m
    x_int = ix - RADIUS
    with np.errstate(invalid="ignore", divide="ignore"):
        x_cm = np.where(den > 0, x_int + num / (2.0 * den), x_int).astype(np.float64)
    rejected = ~(strength >= params.min_corr)
    x_cm[rejected] = np.nan
    return CentreOfMass(x_int.astype(np.float64), x_cm, np.where(rejected, 0.0, strength), den)
