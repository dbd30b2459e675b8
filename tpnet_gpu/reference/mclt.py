"""Golden reference: forward and inverse MCLT of 16x16 tiles (tile_processor.md §1.4, §3, §4, §7.1, §7.2).

Float64 NumPy, one function per step, batched over leading axes. Not used by the fast path: it is the oracle
the kernels are tested against.

Convention (corner-based coordinates: pixel (x, y) covers [x, x+1) x [y, y+1))
----------------------------------------------------------------------------
A tile centre X (continuous) gives the fractional window corner p = X - 8, the integer corner
``itl = floor(p + 0.5)`` and the residual ``s = itl - p`` in (-0.5, 0.5]. Pixels itl .. itl+15 are read; window
sample n sits at t = n + s from p. The finished transform is

    F_q[ky, kx] = 1/4 sum x[ny, nx] w(t_y) phi_{q>>1}(omega_ky (t_y + 4.5)) w(t_x) phi_{q&1}(omega_kx (t_x + 4.5))

computed as: shifted window -> fold 16 -> 8 -> DCT-IV/DST-IV ("pre-rotation", phase origin at t = n) ->
optional kernel product -> phase rotation by s.
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import operators, tables
from tpnet_gpu.reference.products import bmul
from tpnet_gpu.reference.transforms import dtt4

N = tables.DTT_SIZE
N2 = tables.TILE_SIZE


# --- tile centres, integer window pick ---------------------------------------------------------------------
def tile_centres(tiles_y: int, tiles_x: int) -> np.ndarray:
    """Centres (x, y) = (8 tx + 4, 8 ty + 4) of the tile grid, shape ``(tiles_y, tiles_x, 2)``."""
    ty, tx = np.meshgrid(np.arange(tiles_y), np.arange(tiles_x), indexing="ij")
    return np.stack([N * tx + N // 2, N * ty + N // 2], axis=-1).astype(np.float64)


def split_centre(centre) -> tuple[np.ndarray, np.ndarray]:
    """Integer corner and residual of tile centres (§1.4): ``itl = floor(X - 8 + 0.5)``, ``s = itl - (X - 8)``.

    Returns ``(itl, s)`` with the shape of ``centre`` (int64 and float64); s lies in (-0.5, 0.5].
    """
    p = np.asarray(centre, dtype=np.float64) - N
    itl = np.floor(p + 0.5)
    return itl.astype(np.int64), itl - p


def pair_clamp(q, size: int) -> np.ndarray:
    """Pair-preserving clamp of pixel indices (§1.4, Java): q < 0 -> q & 1, q >= size -> size - 2 + (q & 1).

    Keeps the Bayer parity of every index, so a clamped read of a zero-filled colour plane stays on its lattice.
    """
    q = np.asarray(q, dtype=np.int64)
    return np.where(q < 0, q & 1, np.where(q >= size, size - 2 + (q & 1), q))


def extract_windows(plane, itl) -> tuple[np.ndarray, np.ndarray]:
    """Read 16x16 windows with the pair-preserving clamp.

    plane: ``(..., H, W)`` (leading axes, e.g. colours, are kept); itl: ``(T..., 2)`` integer corners (x, y).
    Returns ``windows (..., T..., 16, 16)`` and ``inside (T...)``: True where the window lies fully in the image.
    """
    plane = np.asarray(plane, dtype=np.float64)
    height, width = plane.shape[-2:]
    itl = np.asarray(itl, dtype=np.int64)
    n = np.arange(N2)
    cols = pair_clamp(itl[..., 0, None] + n, width)  # (T..., 16)
    rows = pair_clamp(itl[..., 1, None] + n, height)
    windows = plane[..., rows[..., :, None], cols[..., None, :]]
    inside = (
        (itl[..., 0] >= 0) & (itl[..., 0] + N2 <= width) & (itl[..., 1] >= 0) & (itl[..., 1] + N2 <= height)
    )
    return windows, inside


# --- forward MCLT ---------------------------------------------------------------------------------------------
def shifted_window(s) -> np.ndarray:
    """Half-sine window at the fractional sample positions, ``w(n + s)`` for n = 0..15, shape ``(..., 16)``."""
    return tables.half_sine(np.arange(N2) + np.asarray(s, dtype=np.float64)[..., None])


def fold(x, sx, sy) -> np.ndarray:
    """Window and fold a 16x16 window into the four 8x8 quadrant buffers (§3.2 steps 1-2).

    x: ``(..., 16, 16)`` [row, col]; sx, sy: residuals broadcastable to ``x.shape[:-2]``.
    Returns u ``(..., 4, 8, 8)``: u_q = P_{q>>1} diag(w(n + sy)) x diag(w(n + sx)) P_{q&1}^T.
    """
    x = np.asarray(x, dtype=np.float64)
    batch = x.shape[:-2]
    wx = np.broadcast_to(shifted_window(sx), batch + (N2,))
    wy = np.broadcast_to(shifted_window(sy), batch + (N2,))
    xw = x * wy[..., :, None] * wx[..., None, :]
    p = (tables.fold_matrix(sine=False), tables.fold_matrix(sine=True))
    return np.stack([p[q >> 1] @ xw @ p[q & 1].T for q in range(4)], axis=-3)


def dtt4_2d(u) -> np.ndarray:
    """DCT-IV/DST-IV of each folded quadrant (§3.2 step 3): rows (x) sine iff q&1, columns (y) sine iff q>>1."""
    u = np.asarray(u, dtype=np.float64)
    out = [dtt4(dtt4(u[..., q, :, :], sine=bool(q & 1), axis=-1), sine=bool(q >> 1), axis=-2) for q in range(4)]
    return np.stack(out, axis=-3)


def rotate(f, sx, sy) -> np.ndarray:
    """Phase rotation by a fractional shift (§4): Q <- Q (cos bx + i sin bx)(cos by + j sin by).

    f: ``(..., 4, 8, 8)``; sx, sy broadcastable to ``f.shape[:-3]``; b_x = omega_kx sx, b_y = omega_ky sy.
    Moves content by +s (right / down); turns the pre-rotation transform (samples at t = n) into the one
    with samples at t = n + s.
    """
    f = np.asarray(f, dtype=np.float64)
    bx = np.asarray(sx, dtype=np.float64)[..., None, None] * tables.omega()[None, :]  # (..., 1, 8) over kx
    by = np.asarray(sy, dtype=np.float64)[..., None, None] * tables.omega()[:, None]  # (..., 8, 1) over ky
    cc, sc, cs, ss = (f[..., q, :, :] for q in range(4))
    cx, snx = np.cos(bx), np.sin(bx)
    cc, sc = cc * cx - sc * snx, cc * snx + sc * cx
    cs, ss = cs * cx - ss * snx, cs * snx + ss * cx
    cy, sny = np.cos(by), np.sin(by)
    cc, cs = cc * cy - cs * sny, cc * sny + cs * cy
    sc, ss = sc * cy - ss * sny, sc * sny + ss * cy
    return np.stack([cc, sc, cs, ss], axis=-3)


def mclt_prerotation(x, sx, sy) -> np.ndarray:
    """Windowed, folded, DTT-IV transformed tile, phase origin at the integer samples, ``(..., 4, 8, 8)``."""
    return dtt4_2d(fold(x, sx, sy))


def mclt(x, sx=0.0, sy=0.0) -> np.ndarray:
    """Forward MCLT of 16x16 windows at residual (sx, sy), ``(..., 16, 16) -> (..., 4, 8, 8)`` (§3.1)."""
    return rotate(mclt_prerotation(x, sx, sy), sx, sy)


# --- Bayer --------------------------------------------------------------------------------------------------
def bayer_planes(mosaic, cfa: str = tables.DEFAULT_CFA) -> np.ndarray:
    """Split a Bayer mosaic ``(H, W)`` into zero-filled colour planes ``(3, H, W)`` in R, B, G order.

    Green is multiplied by ``GREEN_PRESCALE`` (0.5) so every colour has density weight 1/4 (§1.1).
    """
    mosaic = np.asarray(mosaic, dtype=np.float64)
    colour = tables.cfa_colour_index(cfa, *mosaic.shape)
    scale = np.array([1.0, 1.0, tables.GREEN_PRESCALE])
    return np.stack([np.where(colour == c, mosaic * scale[c], 0.0) for c in range(3)])


# --- whole tiles from planes ----------------------------------------------------------------------------------
def convert_tiles(planes, centres, kernels=None) -> tuple[np.ndarray, np.ndarray]:
    """Frequency-domain tiles of colour planes at continuous tile centres (§3.2, kernel product §5.2, §4).

    planes: ``(C, H, W)`` (C = 3 zero-filled Bayer colours R, B, G, or 1 for mono); centres: ``(T..., 2)`` (x, y)
    in that camera's pixels; kernels: optional CLT kernels broadcastable to ``(T..., C, 4, 8, 8)``.
    Returns ``(F, inside)``: F ``(T..., C, 4, 8, 8)``, inside ``(T...)`` (window fully in the image; tiles
    that are not read clamped pixels).
    """
    planes = np.asarray(planes, dtype=np.float64)
    itl, s = split_centre(centres)
    windows, inside = extract_windows(planes, itl)  # (C, T..., 16, 16)
    windows = np.moveaxis(windows, 0, -3)  # (T..., C, 16, 16)
    sx, sy = s[..., 0, None], s[..., 1, None]  # broadcast over C
    f = mclt_prerotation(windows, sx, sy)
    if kernels is not None:
        f = bmul(kernels, f)
    return rotate(f, sx, sy), inside


# --- inverse MCLT and overlap-add ------------------------------------------------------------------------------
def imclt(f) -> np.ndarray:
    """Inverse MCLT of tiles (§7.1), ``(..., 4, 8, 8) -> (..., 16, 16)``.

    out[r, c] = w(r) w(c) / 16 sum_q sum X_q[ky, kx] phi_{q>>1}(omega_ky (r + 4.5)) phi_{q&1}(omega_kx (c + 4.5)).
    For f = mclt(x) at s = 0 this is w(r)^2 w(c)^2 x.
    """
    f = np.asarray(f, dtype=np.float64)
    g = operators.inverse_axes()
    return sum(g[q >> 1] @ f[..., q, :, :] @ g[q & 1].T for q in range(4))


def overlap_add(tiles, height: int, width: int) -> np.ndarray:
    """Overlap-add a grid of 16x16 pixel tiles ``(..., tiles_y, tiles_x, 16, 16)`` at stride 8 (§7.2).

    Tile (tx, ty) lands on image pixels 8tx-4 .. 8tx+11 (rows likewise); returns ``(..., height, width)``.
    """
    tiles = np.asarray(tiles, dtype=np.float64)
    tiles_y, tiles_x = tiles.shape[-4:-2]
    out = np.zeros(tiles.shape[:-4] + (height + N, width + N))
    for ty in range(tiles_y):
        for tx in range(tiles_x):
            out[..., N * ty : N * ty + N2, N * tx : N * tx + N2] += tiles[..., ty, tx, :, :]
    return out[..., N // 2 : N // 2 + height, N // 2 : N // 2 + width]
