"""Twin-only math shared by the NumPy and the PyTorch twins (float64 NumPy; each twin casts and caches): the
closed-form expansion of the per-tile bases, the signs of the conjugate bicomplex product and the correlation's
per-frequency colour weights. The operators both twins also use (colour masks, frequency-to-lag matrix) are the
project's, from ``tpnet_gpu.operators``."""

from __future__ import annotations

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.layout import CORR_SIDE, DTT_SIZE, TILE_SIZE

# Short names for the twins' formulas (the sizes themselves live in tpnet_gpu.layout).
N = DTT_SIZE  # 8: frequencies per axis
WIN = TILE_SIZE  # 16: window side
SIDE = CORR_SIDE  # 15: correlation side


def basis_expansion() -> np.ndarray:
    """Fixed ``(32, 256)`` matrix E with basis(s).flat = features(s) @ E, float64.

    The per-tile forward basis is B[n, (phi, k)] = 1/2 w(n + s) phi(omega_k (n + s + 4.5)) (phi = cos, sin) and
    features(s) = [cos b cos g_k, cos b sin g_k, sin b cos g_k, sin b sin g_k] (b = pi s / 16, g_k = omega_k s,
    k = 0..7). With alpha_n = pi (2n + 1) / 32 and theta_nk = omega_k (n + 4.5):
    1/2 w(n + s) cos|sin(omega_k (n + s + 4.5)) = 1/2 sin(alpha_n + beta) cos|sin(theta_nk + gamma_k), which the
    angle-sum formulas expand into 4 products cos|sin(beta) x cos|sin(gamma_k) with fixed coefficients.
    """
    n = np.arange(WIN)[:, None]
    alpha = np.pi * (2 * n + 1) / 32.0  # (16, 1)
    theta = (n + 4.5) * tables.omega()[None, :]  # (16, 8)
    sa, ca, st, ct = np.sin(alpha), np.cos(alpha), np.sin(theta), np.cos(theta)
    coef = 0.5 * np.array(
        [  # [feature, phi = cos | sin, n, k]
            [sa * ct, sa * st],  # cos(beta) cos(gamma_k)
            [-sa * st, sa * ct],  # cos(beta) sin(gamma_k)
            [ca * ct, ca * st],  # sin(beta) cos(gamma_k)
            [-ca * st, ca * ct],  # sin(beta) sin(gamma_k)
        ]
    )
    # Feature (j, k') feeds only the columns of frequency k = k': [j, k', n, phi, k].
    expansion = np.einsum("jpnk,kl->jlnpk", coef, np.eye(N))
    return expansion.reshape(4 * N, WIN * 2 * N)


def conj_product_signs() -> np.ndarray:
    """Signs ``(4, 16)`` [q, (i, j)] of conj(A) * B per frequency (§6.2): X_q = sum_ij signs[q, ij] A_i B_j."""
    terms = (
        ((0, 0, 1), (1, 1, 1), (2, 2, 1), (3, 3, 1)),  # CC = A0 B0 + A1 B1 + A2 B2 + A3 B3
        ((0, 1, 1), (1, 0, -1), (2, 3, 1), (3, 2, -1)),  # SC = A0 B1 - A1 B0 + A2 B3 - A3 B2
        ((0, 2, 1), (2, 0, -1), (1, 3, 1), (3, 1, -1)),  # CS = A0 B2 - A2 B0 + A1 B3 - A3 B1
        ((0, 3, 1), (3, 0, 1), (1, 2, -1), (2, 1, -1)),  # SS = A0 B3 + A3 B0 - A1 B2 - A2 B1
    )
    signs = np.zeros((4, 4, 4))
    for q, quadrant in enumerate(terms):
        for i, j, sign in quadrant:
            signs[q, i, j] = sign
    return signs.reshape(4, 16)


def correlation_weights(colours: int, colour_weights=None, sigma_rb: float = tables.CORR_SIGMA_RB,
                        sigma_corr: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-frequency colour weights ``(colours, 64)`` and the final low-pass filter ``(64,)`` of the correlation.

    X = (w_R P_R + w_B P_B) L(sigma_rb) + w_G P_G = sum_c weight_c P_c (mono: w P), then L(sigma_corr) after the
    normalisation. ``None`` takes the GPU path's default for ``colours`` and the values are checked, both by
    ``CorrelationConfig.resolved``: weights (0.25, 0.25, 0.5) or (1,), sigma_corr 0.9 or 0.15 (mono); sigmas are
    variances (tables.lpf).
    """
    config = CorrelationConfig(colour_weights=None if colour_weights is None else tuple(colour_weights),
                               sigma_rb=sigma_rb, sigma_corr=sigma_corr).resolved(colours)
    weights = np.array(config.colour_weights, dtype=np.float64)[:, None, None] * np.ones((colours, N, N))
    if colours == 3:
        weights[:2] *= tables.lpf(config.sigma_rb)
    return weights.reshape(colours, N * N), tables.lpf(config.sigma_corr).reshape(N * N)
