"""Hand-crafted baseline, first half: pair correlations -> disparity "strips" -> their combination -> integer
maximum and windowed centre of mass (geometry_and_lma.md B.3, C.1-C.3). One torch implementation, vectorised
over tiles: NumPy in gives NumPy out; torch in stays on its device (the frame pipeline uses it on the GPU).

Units: lags in pixels; a strip column s (-7..7) is a position along the pair's disparity axis in disparity
units (the adjacent-pair shift), so a residual disparity delta puts every strip's peak at s = -delta.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tpnet_gpu import tables

RADIUS = tables.CORR_RADIUS
STRIP_ROWS = 9  # corr_strip_hight
STRIP_COLS = 2 * RADIUS + 1
# Pair directions u (first -> second camera) in lag units, quad order (geometry_and_lma.md B.1).
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


def _sampling_matrix() -> tuple[np.ndarray, np.ndarray]:
    """Strips as a linear map: ``(6, 225, 135)`` weights taking a pair's 15x15 correlation to its 9x15 strip
    (bilinear sampling, mean of the two sides), and a ``(6, 135)`` mask of the cells that fall inside +-7."""
    matrix = np.zeros((6, STRIP_COLS * STRIP_COLS, STRIP_ROWS * STRIP_COLS))
    inside = np.ones((6, STRIP_ROWS * STRIP_COLS), dtype=bool)
    for pair in range(6):
        xs, ys = _strip_positions(pair)
        for x, y in zip(xs, ys):  # the two sides of the axis
            x, y = x.ravel(), y.ravel()
            inside[pair] &= (np.abs(x) <= RADIUS) & (np.abs(y) <= RADIUS)
            cx, cy = np.clip(x + RADIUS, 0, 2 * RADIUS), np.clip(y + RADIUS, 0, 2 * RADIUS)
            x0 = np.minimum(np.floor(cx).astype(int), 2 * RADIUS - 1)
            y0 = np.minimum(np.floor(cy).astype(int), 2 * RADIUS - 1)
            fx, fy = cx - x0, cy - y0
            cell = np.arange(len(x))
            for dy, dx, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
                np.add.at(matrix[pair], ((y0 + dy) * STRIP_COLS + x0 + dx, cell), 0.5 * w)
    return matrix, inside


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


_MATRIX, _INSIDE = _sampling_matrix()
_TABLES: dict = {}  # (device, dtype) -> the sampling tables there: uploaded once, not per frame


def _tables(device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    key = (str(device), dtype)
    if key not in _TABLES:
        _TABLES[key] = (torch.as_tensor(_MATRIX, dtype=dtype, device=device), torch.as_tensor(_INSIDE, device=device))
    return _TABLES[key]


def _as_tensor(a) -> torch.Tensor:
    return a if isinstance(a, torch.Tensor) else torch.from_numpy(np.asarray(a, dtype=np.float64))


def _like(result: torch.Tensor, source):
    """NumPy out for NumPy in (CPU), torch out (same device) for torch in."""
    return result if isinstance(source, torch.Tensor) else result.detach().cpu().numpy()


def pair_strips(corr):
    """Strips ``(T, 6, 9, 15)`` of pair correlations ``(T, 6, 15, 15)`` (B.3): row 0 the disparity axis,
    row r the mean of the two points r/2 disparity units off the axis (odd rows shifted half a step); NaN
    outside +-7. NumPy or torch (any device: one matrix product per pair, no host copy)."""
    c = _as_tensor(corr)
    if c.dim() != 4 or tuple(c.shape[1:]) != (6, STRIP_COLS, STRIP_COLS):
        raise ValueError(f"corr: expected shape (tiles, 6, 15, 15), got {tuple(c.shape)}")
    matrix, inside = _tables(c.device, c.dtype)
    flat = c.reshape(c.shape[0], 6, -1)
    strips = torch.einsum("tpi,pio->tpo", flat, matrix)
    strips = torch.where(inside, strips, torch.full_like(strips, float("nan")))
    return _like(strips.reshape(c.shape[0], 6, STRIP_ROWS, STRIP_COLS), corr)


def combine_strips(strips, offset: float = 0.1, pairs=None):
    """Combine pair strips ``(T, 6, 9, 15)`` into ``(T, 9, 15)``: with offset o >= 0 the geometric mean of
    max(strip + o, 0) minus o (0 stays 0); o < 0 the arithmetic mean. ``pairs``: optional bool mask (6,)."""
    s = _as_tensor(strips)
    if pairs is not None:
        s = s[:, torch.as_tensor(np.asarray(pairs, dtype=bool), device=s.device)]
    if offset < 0:
        return _like(s.mean(dim=1), strips)
    geo = torch.exp(torch.log(torch.clamp(s + offset, min=0.0)).mean(dim=1))
    return _like(torch.where(geo > 0, geo - offset, torch.zeros_like(geo)), strips)


@dataclass(frozen=True)
class CentreOfMass:
    """Per-tile result of C.1 steps 2-3: ``x_int`` integer argmax lag, ``x_cm`` refined lag (NaN where
    rejected), ``strength`` value at the argmax, ``weight`` sum of the CM weights; shapes ``(T,)``, NumPy or
    torch as the input."""

    x_int: np.ndarray
    x_cm: np.ndarray
    strength: np.ndarray
    weight: np.ndarray

    @property
    def disparity(self):
        """Residual disparity -x_cm (px)."""
        return -self.x_cm


def centre_of_mass(combo, params: StripParams = StripParams()) -> CentreOfMass:
    """Integer maximum of row 0 and the windowed centre of mass over rows 0 and 1 (C.2, C.3), ``(T, 9, 15)``."""
    c = _as_tensor(combo)
    row0 = torch.where(torch.isfinite(c[:, 0]), c[:, 0], torch.full_like(c[:, 0], -float("inf")))
    ix = torch.argmax(row0, dim=1)
    strength = torch.gather(row0, 1, ix[:, None])[:, 0]
    num = torch.zeros_like(strength)
    den = torch.zeros_like(strength)
    for row, row_weight in ((0, WINDOW_Y[0]), (1, 2.0 * WINDOW_Y[1])):
        for h in range(-8, 9):
            if (h - row) % 2:
                continue
            col = ix + h // 2
            ok = (col >= 0) & (col < STRIP_COLS)
            v = torch.gather(c[:, row], 1, col.clamp(0, STRIP_COLS - 1)[:, None])[:, 0]
            use = ok & torch.isfinite(v) & (v > 0)
            m = torch.where(use, v, torch.zeros_like(v)) * float(WINDOW_X[abs(h)] * row_weight)
            num = num + m * h
            den = den + m
    x_int = (ix - RADIUS).to(c.dtype)
    x_cm = torch.where(den > 0, x_int + num / (2.0 * torch.where(den > 0, den, torch.ones_like(den))), x_int)
    rejected = ~(strength >= params.min_corr)
    x_cm = torch.where(rejected, torch.full_like(x_cm, float("nan")), x_cm)
    strength = torch.where(rejected, torch.zeros_like(strength), strength)
    return CentreOfMass(*(_like(v, combo) for v in (x_int, x_cm, strength, den)))
