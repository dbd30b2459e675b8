"""Vectorised float32 NumPy tile processor: the CPU peer the Warp kernels are benchmarked against.

Same math as ``kernels/convert.py`` and ``kernels/correlate.py`` (tile_processor.md §1.4, §3.1, §6.2, §6.3), batched
over all tiles with matrix products; Python loops run only over cameras, pairs and quadrants. Float32
throughout. Not the oracle: that is ``tpnet_gpu.reference`` (float64), which this module deliberately does not
import (tests/bench/twins/test_numpy_tp.py checks both). No aberration kernels, no validity masks: inputs must be
finite.

Convert, per camera (all tiles at once):
    p = centre - 8, itl = floor(p + 0.5), s = itl - p
    x = 16x16 window at (itl_y, itl_x), pixels read with the pair-preserving clamp (via a padded frame)
    x_c = x * mask_c (zero-fill Bayer mask of colour c = R, B, G, green scaled by 0.5; mono: no mask)
    F_q = Bv[q >> 1] @ x_c @ Bh[q & 1].T    (q = CC, SC, CS, SS)
with the closed-form per-tile bases (§13) B[phi](s)[k, n] = 1/2 w(n + s) phi(omega_k (n + s + 4.5)), phi = cos,
sin, Bh from s_x and Bv from s_y: batched small matmuls over all tiles, as in the Warp kernel. The bases of all
tiles come from one GEMM (they are a fixed linear function of cos/sin of pi s / 16 and omega_k s).

Correlate, per pair (all tiles at once): the conjugate bicomplex product conj(A_c) B_c per colour, summed with
per-frequency colour weights (w_R, w_B times L(sigma_rb), w_G) - one einsum for the 16 quadrant products A_i B_j,
one matmul with their signs -, the fat-zero normalisation, L(sigma_corr), then one GEMM with the fixed
(256 -> 225) frequency-to-lag matrix sum_q kron(L_{q>>1}, L_{q&1}) (§6.3).

Work buffers are allocated once per call and reused across cameras / pairs: fresh large temporaries cost a page
fault per 4 KiB on every use, which on small VMs is a visible share of the run time. The colour masks and the
frequency-to-lag matrix are the project's operators (``tpnet_gpu.operators``), the sizes and the frame padding
``PAD`` its layout (``tpnet_gpu.layout``); the basis expansion, the product signs and the correlation weights are
shared with the PyTorch twin (``twins/common.py``).
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from tpnet_gpu import operators, tables
from tpnet_gpu.layout import HALF_TILE, PAD

from tpnet_gpu.bench.twins.common import N, SIDE, WIN, basis_expansion, conj_product_signs, correlation_weights

__all__ = ["numpy_convert", "numpy_correlate"]


# --- convert ----------------------------------------------------------------------------------------------------
def _split_centres(centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer window corner (int64) and residual s (float32) of centres ``(T, 2)`` (x, y), float32 arithmetic."""
    p = centres - np.float32(HALF_TILE)
    itl = np.floor(p + np.float32(0.5))
    return itl.astype(np.int64), itl - p


def _pair_clamp(q: np.ndarray, size: int) -> np.ndarray:
    """Pair-preserving clamp: q < 0 -> q & 1, q >= size -> size - 2 + (q & 1)."""
    return np.where(q < 0, q & 1, np.where(q >= size, size - 2 + (q & 1), q))


def _padded_corner(itl: np.ndarray, size: int) -> np.ndarray:
    """Corner in the padded frame of windows with image corner ``itl``; windows wholly off the image are moved
    next to it by an even amount (they read only parity-dependent clamped pixels, so nothing changes)."""
    corner = np.where(itl < -WIN, -WIN - (itl & 1), itl)
    corner = np.where(corner > size, size + ((corner - size) & 1), corner)
    return corner + PAD


def _windows(frame: np.ndarray, itl: np.ndarray) -> np.ndarray:
    """16x16 windows ``(T, 16, 16)`` of one frame ``(H, W)`` at integer corners ``itl (T, 2)``, pair-clamped."""
    height, width = frame.shape
    rows = _pair_clamp(np.arange(-PAD, height + PAD), height)
    cols = _pair_clamp(np.arange(-PAD, width + PAD), width)
    padded = frame[np.ix_(rows, cols)]
    views = sliding_window_view(padded, (WIN, WIN))  # (H + 2 PAD - 15, W + 2 PAD - 15, 16, 16), no copy
    return views[_padded_corner(itl[:, 1], height), _padded_corner(itl[:, 0], width)]


_BASIS_EXPANSION = basis_expansion().astype(np.float32)


def _basis(s: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Per-tile forward bases into ``out (T, 16, 16)`` [n, (phi, k)] = 1/2 w(n + s) phi(omega_k (n + s + 4.5)).

    One GEMM: features (T, 32) = [cos b cos g_k, cos b sin g_k, sin b cos g_k, sin b sin g_k] (b = pi s / 16,
    g_k = omega_k s) times the fixed expansion (``twins.common.basis_expansion``). Only 9 angles per tile are
    evaluated and the phase omega_k (n + 4.5) stays exact (float64 table).
    """
    beta = (np.float32(np.pi / 16) * s)[:, None, None]  # (T, 1, 1)
    gamma = (s[:, None] * tables.omega().astype(np.float32)[None, :])[:, None, :]  # (T, 1, 8)
    cb, sb, cg, sg = np.cos(beta), np.sin(beta), np.cos(gamma), np.sin(gamma)
    features = np.concatenate([cb * cg, cb * sg, sb * cg, sb * sg], axis=1)  # (T, 4, 8)
    np.matmul(features.reshape(-1, 4 * N), _BASIS_EXPANSION, out=out.reshape(-1, WIN * 2 * N))
    return out


def numpy_convert(frames, centres, cfa: str | None = tables.DEFAULT_CFA) -> np.ndarray:
    """CLT tiles ``(tiles, cams, colours, 4, 8, 8)`` float32 of raw frames at per-camera tile centres.

    frames: ``(cams, H, W)`` raw Bayer mosaics in ``cfa`` (or mono for ``cfa=None``), float32 (other dtypes are
    converted once); centres: ``(tiles, cams, 2)`` (x, y) in pixels, finite. Colours R, B, G (or 1 for mono);
    quadrants CC, SC, CS, SS.
    """
    frames = np.asarray(frames, dtype=np.float32)
    centres = np.asarray(centres, dtype=np.float32)
    if frames.ndim != 3 or centres.ndim != 3 or centres.shape[1:] != (frames.shape[0], 2):
        raise ValueError(
            f"frames, centres: expected (cams, H, W) and (tiles, cams, 2), got {frames.shape} and {centres.shape}"
        )
    cams = frames.shape[0]
    tiles = centres.shape[0]
    masks = operators.colour_masks(cfa).astype(np.float32)
    colours = masks.shape[1]
    clt = np.empty((tiles, cams, colours, 4, N, N), dtype=np.float32)
    # Work buffers, reused for every camera.
    x = np.empty((tiles, colours, WIN, WIN), dtype=np.float32)  # masked windows [row, col]
    bh = np.empty((tiles, WIN, 2 * N), dtype=np.float32)  # [n, (phi_x, kx)]
    bv = np.empty((tiles, WIN, 2 * N), dtype=np.float32)  # [n, (phi_y, ky)]
    h = np.empty((tiles, colours, WIN, 2 * N), dtype=np.float32)  # [row, (phi_x, kx)]
    for cam in range(cams):
        itl, s = _split_centres(centres[:, cam])
        windows = _windows(frames[cam], itl)  # (T, 16, 16)
        parity = 2 * (itl[:, 1] & 1) + (itl[:, 0] & 1)
        np.take(masks, parity, axis=0, out=x, mode="clip")  # (mode "raise" would buffer the output)
        x *= windows[:, None]
        _basis(s[:, 0], out=bh)
        _basis(s[:, 1], out=bv)
        np.matmul(x, bh[:, None], out=h)  # both horizontal transforms of every row
        bv_t = bv.transpose(0, 2, 1)[:, None]  # (T, 1, (phi_y, ky), n)
        for q in range(4):  # F_q = Bv[q >> 1] @ x @ Bh[q & 1].T, written in place
            rows, cols = slice(N * (q >> 1), N * (q >> 1) + N), slice(N * (q & 1), N * (q & 1) + N)
            np.matmul(bv_t[:, :, rows], h[..., cols], out=clt[:, cam, :, q])
    return clt


# --- correlate --------------------------------------------------------------------------------------------------
_CONJ_PRODUCT_SIGNS = conj_product_signs().astype(np.float32)


def numpy_correlate(
    clt,
    pairs=tables.QUAD_PAIRS,
    colour_weights=None,
    fat_zero: float = tables.CORR_FAT_ZERO,
    sigma_rb: float = tables.CORR_SIGMA_RB,
    sigma_corr: float | None = None,
) -> np.ndarray:
    """Pixel-domain pair correlations ``(tiles, len(pairs), 15, 15)`` float32 of CLT tiles.

    clt: ``(tiles, cams, colours, 4, 8, 8)`` (colours 3 = R, B, G or 1 = mono); pairs: (first, second) cameras.
    Defaults as the GPU path: weights (0.25, 0.25, 0.5) or (1,), sigma_corr 0.9 or 0.15 (mono); sigmas are
    variances (tables.lpf). Row = vertical lag + 7, column = horizontal lag + 7.
    """
    clt = np.asarray(clt, dtype=np.float32)
    if clt.ndim != 6 or clt.shape[2] not in (1, 3) or clt.shape[3:] != (4, N, N):
        raise ValueError(f"clt: expected (tiles, cams, 1 or 3, 4, 8, 8), got {clt.shape}")
    tiles, _, colours = clt.shape[:3]
    # X = (w_R P_R + w_B P_B) L_rb + w_G P_G = sum_c weight_c P_c with per-frequency weights (C, 64).
    weights, lpf_corr = (w.astype(np.float32) for w in correlation_weights(colours, colour_weights, sigma_rb,
                                                                             sigma_corr))
    fz2 = np.float32(fat_zero) ** 2
    to_lags = operators.lag_matrix().astype(np.float32)
    corr = np.empty((tiles, len(pairs), SIDE * SIDE), dtype=np.float32)
    # Work buffers, reused for every pair.
    products = np.empty((tiles, 4, 4, N * N), dtype=np.float32)  # [i, j]: sum_c weight_c A_i B_j
    x = np.empty((tiles, 4, N * N), dtype=np.float32)
    flat = (tiles, colours, 4, N * N)
    for p, (a, b) in enumerate(pairs):
        np.einsum("tcif,tcjf,cf->tijf", clt[:, a].reshape(flat), clt[:, b].reshape(flat), weights, out=products)
        np.matmul(_CONJ_PRODUCT_SIGNS, products.reshape(tiles, 16, N * N), out=x)  # X = sum_c w_c conj(A_c) B_c
        norm2 = fz2 + np.einsum("tqf,tqf->tf", x, x)
        scale = np.zeros_like(norm2)
        np.divide(lpf_corr, np.sqrt(norm2), out=scale, where=norm2 > 0)  # L_corr / |X|, 0 where |X| = fz = 0
        x *= scale[:, None]
        np.matmul(x.reshape(tiles, 4 * N * N), to_lags, out=corr[:, p])
    return corr.reshape(tiles, len(pairs), SIDE, SIDE)
