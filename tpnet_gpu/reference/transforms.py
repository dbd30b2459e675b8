"""Golden reference: the 8-point transforms, applied along one axis (tile_processor.md §2). Float64, NumPy.

All four transforms act on the *last* axis by default; every other axis is a batch axis.
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import tables


def _apply(matrix: np.ndarray, x: np.ndarray, axis: int) -> np.ndarray:
    x = np.moveaxis(np.asarray(x, dtype=np.float64), axis, -1)
    if x.shape[-1] != tables.DTT_SIZE:
        raise ValueError(f"x: expected {tables.DTT_SIZE} samples along axis {axis}, got {x.shape[-1]}")
    return np.moveaxis(x @ matrix.T, -1, axis)


def dct4(x, axis: int = -1) -> np.ndarray:
    """DCT-IV, ``y[k] = 1/2 sum_n x[n] cos(pi(2n+1)(2k+1)/32)``; orthonormal, self-inverse."""
    return _apply(tables.dtt4_matrix(sine=False), x, axis)


def dst4(x, axis: int = -1) -> np.ndarray:
    """DST-IV, ``y[k] = 1/2 sum_n x[n] sin(pi(2n+1)(2k+1)/32)``; orthonormal, self-inverse."""
    return _apply(tables.dtt4_matrix(sine=True), x, axis)


def dct2e(x, axis: int = -1) -> np.ndarray:
    """DCT-II "e", ``y[m] = 1/2 sum_k x[k] cos(pi m(2k+1)/16)`` (= 0.25 * scipy dct type 2)."""
    return _apply(tables.dtt2e_matrix(sine=False), x, axis)


def dst2e(x, axis: int = -1) -> np.ndarray:
    """DST-II "e", ``y[m] = 1/2 sum_k x[k] sin(pi (m+1)(2k+1)/16)`` (= 0.25 * scipy dst type 2)."""
    return _apply(tables.dtt2e_matrix(sine=True), x, axis)


def dtt4(x, sine: bool, axis: int = -1) -> np.ndarray:
    """DST-IV if ``sine`` else DCT-IV, along ``axis``."""
    return dst4(x, axis) if sine else dct4(x, axis)
