"""Constants and small float64 tables of the tile processor (spec: tile_processor.md §1, §2, §3.2, §6, §9).

This is the one description of the math's *tables* (windows, fold map, 8-point transform matrices, low-pass
filters, pair and colour order). The golden reference (``tpnet_gpu.reference``) and the fast kernels both
build from it, so neither forks the constants; the tables themselves are tested against scipy and against
the numbers printed in the spec (tests/test_tables.py).

Conventions
-----------
* Tile: 16x16 window at stride 8; ``DTT_SIZE`` N = 8. Frequencies ``omega_k = pi*(2k+1)/16``.
* Transform tile layout ``[q, ky, kx]`` with quadrants q0 = CC, q1 = SC, q2 = CS, q3 = SS; the first letter is
  the horizontal (x) transform, the second the vertical (y) one, so bit 0 of q = "x is sine", bit 1 = "y is sine".
* Colour order everywhere: 0 = R, 1 = B, 2 = G (not RGB).
"""

from __future__ import annotations

import numpy as np

# Sizes live in tpnet_gpu.layout (no Warp import); re-exported here for the tables' users.
from tpnet_gpu.layout import CORR_RADIUS, DTT_SIZE, NET_RADIUS, TILE_SIZE, TILE_STRIDE  # noqa: F401

COLOURS = ("R", "B", "G")
QUADRANTS = ("CC", "SC", "CS", "SS")

# Camera pairs (first, second) of the quad, in the spec's order (tile_processor.md §6.1).
QUAD_PAIRS = ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (2, 1))
QUAD_PAIR_NAMES = ("hor-top", "hor-bottom", "vert-left", "vert-right", "diag-main", "diag-other")

# Ideal quad: camera offsets r_i from the virtual centre camera in baselines (x right, y down), cameras
# 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right; camera i sees a centre-camera point c at c - d r_i
# (geometry_and_lma.md A.1, A.2).
QUAD_OFFSETS = ((-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5))

# Correlation defaults of the GPU path (tile_processor.md §6.5).
CORR_COLOUR_WEIGHTS = (0.25, 0.25, 0.5)  # R, B, G
CORR_FAT_ZERO = 30.0  # absolute, in units of the accumulated product
CORR_SIGMA_RB = 0.5  # LPF applied after R+B are accumulated
CORR_SIGMA = 0.9  # LPF applied after normalisation (colour)
CORR_SIGMA_MONO = 0.15
NET_CORR_OFFSET = 0.1  # corr_offset of the pair combination for the network layers (network.md §1)

# Texture defaults (tile_processor.md §7.3, §9): per-colour low-pass sigmas (R, B, G; mono), colour weights of
# the cameras' comparison (corr_red 0.5, corr_blue 0.2, normalised), difference sigma, shot-noise compression.
TEXTURE_SIGMAS = (0.9, 0.9, 0.6)
TEXTURE_SIGMA_MONO = 0.4
TEXTURE_COLOUR_WEIGHTS = (0.5 / 1.7, 0.2 / 1.7, 1.0 / 1.7)
TEXTURE_DIFF_SIGMA = 5.0
TEXTURE_MIN_SHOT = 10.0
TEXTURE_SCALE_SHOT = 3.0
TEXTURE_WEIGHT_FLOOR = 1e-4  # FAT_ZERO_WEIGHT: keeps every camera's weight positive
TEXTURE_OUTPUT_GAIN = 4.0  # a zero-filled colour reconstructs to ~1/4 of its value (§5.4)

# Bayer: green is prescaled so every colour has density weight 1/4 (tile_processor.md §1.1).
GREEN_PRESCALE = 0.5

# Position (row parity, column parity) of the red pixel for each 2x2 CFA; B is on the opposite corner.
CFA_RED_POSITION = {"GRBG": (0, 1), "RGGB": (0, 0), "BGGR": (1, 1), "GBRG": (1, 0)}
DEFAULT_CFA = "GRBG"


def omega() -> np.ndarray:
    """Frequencies ``pi*(2k+1)/16`` for k = 0..7, shape ``(8,)``."""
    return np.pi * (2 * np.arange(DTT_SIZE) + 1) / 16.0


def half_sine(t) -> np.ndarray:
    """Half-sine window ``w(t) = sin(pi*(2t+1)/32)``; t may be fractional (shifted window), any shape."""
    return np.sin(np.pi * (2 * np.asarray(t, dtype=np.float64) + 1) / 32.0)


def fold_index() -> np.ndarray:
    """Folded index f(n) of window sample n (§3.2): n+4 (n<4), 11-n (4<=n<12), n-12 (n>=12); shape ``(16,)``."""
    n = np.arange(TILE_SIZE)
    return np.where(n < 4, n + 4, np.where(n < 12, 11 - n, n - 12))


def fold_signs(sine: bool) -> np.ndarray:
    """Fold signs sigma_C (cosine branch: +1 for n<4 else -1) or sigma_S (sine: -1 for n>=12 else +1), ``(16,)``."""
    n = np.arange(TILE_SIZE)
    if sine:
        return np.where(n >= 12, -1.0, 1.0)
    return np.where(n < 4, 1.0, -1.0)


def fold_matrix(sine: bool) -> np.ndarray:
    """Signed 16 -> 8 fold as a matrix P, ``(8, 16)``: ``u = P @ x`` with ``P[f(n), n] = sigma(n)``."""
    p = np.zeros((DTT_SIZE, TILE_SIZE))
    p[fold_index(), np.arange(TILE_SIZE)] = fold_signs(sine)
    return p


def dtt4_matrix(sine: bool) -> np.ndarray:
    """8-point DCT-IV (or DST-IV) matrix, ``(8, 8)``: ``y[k] = 1/2 sum_n x[n] cos|sin(pi(2n+1)(2k+1)/32)``.

    Orthonormal and symmetric, hence its own inverse; equals scipy's type-4 transform with ``norm='ortho'``.
    """
    k = np.arange(DTT_SIZE)
    arg = np.pi * np.outer(2 * k + 1, 2 * k + 1) / 32.0
    return 0.5 * (np.sin(arg) if sine else np.cos(arg))


def dtt2e_matrix(sine: bool) -> np.ndarray:
    """8-point DCT-II "e" (or DST-II "e") matrix, ``(8, 8)`` [m, k] (§2).

    DCT-II-e: ``y[m] = 1/2 sum_k x[k] cos(pi*m*(2k+1)/16)`` = 0.25 * scipy ``dct(x, 2)``;
    DST-II-e: ``y[m] = 1/2 sum_k x[k] sin(pi*(m+1)*(2k+1)/16)`` = 0.25 * scipy ``dst(x, 2)``. Not orthogonal.
    """
    m = np.arange(DTT_SIZE)
    lag = m + 1 if sine else m
    arg = np.outer(lag, omega())
    return 0.5 * (np.sin(arg) if sine else np.cos(arg))


def unfold_matrix(sine: bool, radius: int) -> np.ndarray:
    """Lag unfold of a DCT-II-e / DST-II-e output, ``(2r+1, 8)`` [lag + r, index] (§6.3).

    The cosine part is even (lag m reads index |m|), the sine part odd (lag m reads index |m| - 1 with the
    sign of m; lag 0 reads nothing).
    """
    lags = np.arange(-radius, radius + 1)
    u = np.zeros((2 * radius + 1, DTT_SIZE))
    if sine:
        nz = lags != 0
        u[np.nonzero(nz)[0], np.abs(lags[nz]) - 1] = np.sign(lags[nz])
    else:
        u[np.arange(2 * radius + 1), np.abs(lags)] = 1.0
    return u


def lpf(sigma: float) -> np.ndarray:
    """Frequency-domain low-pass table L, ``(8, 8)`` [ky, kx] (§9, "LPF construction").

    ``sigma`` is used as a *variance*, as in the original: g[i, j] = exp(-(i^2 + j^2) / (2 sigma)). g is
    normalised to unit DC response, then L[ky, kx] = 4 sum e_i e_j g[i, j] cos(i omega_ky) cos(j omega_kx)
    with endpoint weights e_0 = e_7 = 1/2. Separable: ``L = outer(l, l)``.
    """
    i = np.arange(DTT_SIZE, dtype=np.float64)
    g1 = np.exp(-(i**2) / (2.0 * sigma))
    m = np.where(i == 0, 1.0, 2.0)
    norm1 = np.sum(g1 * np.cos(np.pi * i / 16) * m)
    g1 = g1 / norm1
    e = np.ones(DTT_SIZE)
    e[0] = e[-1] = 0.5
    l1 = 2.0 * np.cos(np.outer(omega(), i)) @ (e * g1)
    return np.outer(l1, l1)


def cfa_colour_index(pattern: str, rows: int, cols: int) -> np.ndarray:
    """Colour index (0 R, 1 B, 2 G) of every pixel of a ``(rows, cols)`` mosaic with the given 2x2 CFA."""
    red = cfa_red_position(pattern)
    y = np.arange(rows)[:, None] % 2
    x = np.arange(cols)[None, :] % 2
    is_r = (y == red[0]) & (x == red[1])
    is_b = (y == 1 - red[0]) & (x == 1 - red[1])
    return np.where(is_r, 0, np.where(is_b, 1, 2))


def cfa_red_position(pattern: str) -> tuple[int, int]:
    """(row parity, column parity) of the red pixel; raises ``ValueError`` naming the allowed patterns."""
    if pattern not in CFA_RED_POSITION:
        raise ValueError(f"cfa: expected one of {sorted(CFA_RED_POSITION)}, got {pattern!r}")
    return CFA_RED_POSITION[pattern]


def kernel_to_clt(h) -> np.ndarray:
    """CLT form ``[4, 8, 8]`` of a pixel-domain convolution kernel h, ``(2r+1, 2r+1)`` with r <= 7 (§5.3).

    ``h[dy + r, dx + r]`` is the weight in out(y, x) = sum h(dy, dx) in(y - dy, x - dx), so a delta at dx = +1
    moves content one pixel right. K_q[ky, kx] = sum h(dy, dx) phi_{q>>1}(omega_ky dy) phi_{q&1}(omega_kx dx),
    phi_0 = cos, phi_1 = sin. The identity kernel gives K_CC = 1, the rest 0. Multiplying CLT tiles by K
    (bicomplex product) approximates the convolution (the MCLT is lapped: ~2 % error for 3x3 blurs).
    """
    h = np.asarray(h, dtype=np.float64)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or h.shape[0] % 2 != 1 or h.shape[0] > 2 * CORR_RADIUS + 1:
        raise ValueError(f"h: expected a square kernel of odd side <= 15, got shape {h.shape}")
    r = h.shape[0] // 2
    arg = np.outer(omega(), np.arange(-r, r + 1))  # [k, d]
    phi = (np.cos(arg), np.sin(arg))
    return np.stack([phi[q >> 1] @ h @ phi[q & 1].T for q in range(4)])
