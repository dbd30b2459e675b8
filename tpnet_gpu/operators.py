"""Host-built operators of the tile processor, built once here from ``tpnet_gpu.tables`` (float64 NumPy).

Every consumer - the Warp and the Taichi backends, the float64 reference and both benchmark twins - takes these
matrices from this module, so no operator is rebuilt in a second place. The tables they are made of are tested
against scipy and the spec's printed numbers (tests/test_tables.py); the operators against independent sums
(tests/test_operators.py).
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.layout import CORR_RADIUS, CORR_SIDE, DTT_SIZE, TILE_SIZE


def colour_masks(cfa: str | None) -> np.ndarray:
    """Zero-fill colour masks ``(4, colours, 16, 16)`` of a window per corner parity ``2 (itl_y & 1) + (itl_x & 1)``.

    Colours R, B, G (tile_processor.md §1.1); green carries its prescale 0.5. Mono (``cfa`` None): one colour of
    ones. A window whose image corner has that parity reads pixel (r, c) of colour ``k`` iff ``mask[p, k, r, c]``.
    """
    if cfa is None:
        return np.ones((4, 1, TILE_SIZE, TILE_SIZE))
    scale = np.array([1.0, 1.0, tables.GREEN_PRESCALE])
    colour = tables.cfa_colour_index(cfa, TILE_SIZE + 2, TILE_SIZE + 2)
    masks = np.zeros((4, 3, TILE_SIZE, TILE_SIZE))
    for parity in range(4):
        py, px = parity >> 1, parity & 1
        window = colour[py : py + TILE_SIZE, px : px + TILE_SIZE]
        for c in range(3):
            masks[parity, c] = np.where(window == c, scale[c], 0.0)
    return masks


def lag_operator(sine: bool, radius: int = CORR_RADIUS) -> np.ndarray:
    """Per-axis frequency-to-lag operator ``(2r+1, 8)`` [lag + r, k]: 1/2 unfold @ DCT-II-e|DST-II-e (§6.3).

    A correlation spectrum X_q (q = CC, SC, CS, SS; rows vertical) becomes the pixel-domain correlation
    ``sum_q L[q >> 1] @ X_q @ L[q & 1].T`` (row = vertical lag + r).
    """
    return 0.5 * tables.unfold_matrix(sine, radius) @ tables.dtt2e_matrix(sine)


def lag_operators(radius: int = CORR_RADIUS) -> np.ndarray:
    """``(2, 2r+1, 8)``: ``lag_operator`` for cosine (0) and sine (1)."""
    return np.stack([lag_operator(sine, radius) for sine in (False, True)])


def lag_matrix() -> np.ndarray:
    """The whole frequency-to-lag map as one matrix ``(4 * 64, 15 * 15)``: corr.flat = X.flat @ M (X ``(4, 8, 8)``)."""
    lags = lag_operators()
    m = np.stack([np.einsum("ma,nb->abmn", lags[q >> 1], lags[q & 1]) for q in range(4)])  # [q, ky, kx, my, mx]
    return m.reshape(4 * DTT_SIZE * DTT_SIZE, CORR_SIDE * CORR_SIDE)


def half_dtt2e() -> np.ndarray:
    """``(2, 8, 8)`` [sine, m, k]: 1/2 DCT-II-e and 1/2 DST-II-e, the transforms ``lag_operator`` unfolds."""
    return np.stack([0.5 * tables.dtt2e_matrix(sine) for sine in (False, True)])


def unfold_gather(radius: int = CORR_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """The lag unfold as a gather: ``index (2, 2r+1)`` int32 and ``sign (2, 2r+1)`` with
    ``unfold[sine, lag, index[sine, lag]] = sign[sine, lag]`` (0 for the sine part at lag 0)."""
    unfold = [tables.unfold_matrix(sine, radius) for sine in (False, True)]
    index = np.stack([np.abs(u).argmax(axis=1) for u in unfold]).astype(np.int32)
    sign = np.stack([u.sum(axis=1) for u in unfold])
    return index, sign


def inverse_axis(sine: bool) -> np.ndarray:
    """Per-axis inverse-MCLT operator ``(16, 8)`` [n, k]: DTT-IV, unfold with the fold signs, window w(n)/2 (§7.1).

    The inverse of tile X ``(4, 8, 8)`` is ``sum_q G[q >> 1] @ X_q @ G[q & 1].T`` ``(16, 16)``.
    """
    window = 0.5 * tables.half_sine(np.arange(TILE_SIZE))
    return window[:, None] * (tables.fold_matrix(sine).T @ tables.dtt4_matrix(sine))


def inverse_axes() -> np.ndarray:
    """``(2, 16, 8)``: ``inverse_axis`` for cosine (0) and sine (1)."""
    return np.stack([inverse_axis(sine) for sine in (False, True)])


def window_squared() -> np.ndarray:
    """w(r)^2 w(c)^2, ``(16, 16)``: what one tile's inverse MCLT carries before overlap-add (§7.3)."""
    w2 = tables.half_sine(np.arange(TILE_SIZE)) ** 2
    return np.outer(w2, w2)


def shifted_basis_parts() -> tuple[np.ndarray, np.ndarray]:
    """The shift-free parts of the forward basis of tile_processor.md §3.1 / §13, for its evaluation by angle
    addition.

    The basis is ``1/2 w(n + s) cos|sin(omega_k (n + s + 4.5))`` with ``w(n + s) = sin(b_n + theta)``,
    ``b_n = pi (2n + 1) / 32`` and ``omega_k (n + s + 4.5) = phi_kn + (2k + 1) theta``, ``theta = pi s / 16``.
    Returns ``window (2, 16)`` [sin b_n, cos b_n] and ``phase (2, 8, 16)`` [cos phi_kn, sin phi_kn] (k, n), so a
    kernel needs one sine and cosine of theta per axis instead of 2 x 16 x 8.
    """
    b = np.pi * (2 * np.arange(TILE_SIZE) + 1) / 32.0
    phi = np.outer(tables.omega(), np.arange(TILE_SIZE) + 4.5)  # (8, 16)
    return np.stack([np.sin(b), np.cos(b)]), np.stack([np.cos(phi), np.sin(phi)])
