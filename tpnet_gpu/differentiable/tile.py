"""The tile processor's forward math as torch autograd (tile_processor.md §1.4, §3, §4, §6): the same steps as
the float64 NumPy reference (``tpnet_gpu.reference.mclt`` / ``correlation``) on the same tables, so the
forward output equals the reference's (tested) and gradients flow to pixel values and tile centres.

Centres enter through the residual s = itl - (X - 8): the integer window corner ``itl = floor(X - 8 + 0.5)`` is
piecewise constant (no gradient), s moves the half-sine window and rotates the phase (smooth). So the
derivative with respect to a centre is exact between the integer steps of its window corner.

Tensors keep the caller's device and dtype; the tables are built per (device, dtype) once.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from tpnet_gpu import operators, tables

N = tables.DTT_SIZE
N2 = tables.TILE_SIZE


@functools.lru_cache(maxsize=8)
def _tables(device: torch.device, dtype: torch.dtype) -> dict:
    """Fold matrices ``(2, 8, 16)``, DTT-IV matrices ``(2, 8, 8)``, omega ``(8,)``, lag operators ``(2, 15, 8)``."""
    def t(a):
        return torch.as_tensor(np.asarray(a), dtype=dtype, device=device)

    return {"fold": t([tables.fold_matrix(sine=False), tables.fold_matrix(sine=True)]),
            "dtt": t([tables.dtt4_matrix(sine=False), tables.dtt4_matrix(sine=True)]),
            "omega": t(tables.omega()), "lags": t(operators.lag_operators(tables.CORR_RADIUS))}


def bayer_planes(mosaic: torch.Tensor, cfa: str = tables.DEFAULT_CFA) -> torch.Tensor:
    """Zero-filled colour planes ``(..., 3, H, W)`` (R, B, G; green times ``GREEN_PRESCALE``) of mosaics
    ``(..., H, W)``, as ``reference.bayer_planes``."""
    colour = torch.as_tensor(tables.cfa_colour_index(cfa, *mosaic.shape[-2:]), device=mosaic.device)
    scale = (1.0, 1.0, tables.GREEN_PRESCALE)
    return torch.stack([torch.where(colour == c, mosaic * scale[c], torch.zeros_like(mosaic)) for c in range(3)],
                       dim=-3)


def _pair_clamp(q: torch.Tensor, size: int) -> torch.Tensor:
    """``reference.pair_clamp``: indices off the image keep their Bayer parity."""
    return torch.where(q < 0, q & 1, torch.where(q >= size, size - 2 + (q & 1), q))


def extract_windows(planes: torch.Tensor, centres: torch.Tensor):
    """16x16 windows of ``planes (C, H, W)`` at centres ``(T, 2)`` (x, y): ``(windows (T, C, 16, 16), s (T, 2),
    inside (T,))``; ``s`` carries the centres' gradient, the integer corner none."""
    height, width = planes.shape[-2:]
    p = centres - N
    itl = torch.floor(p.detach() + 0.5)
    s = itl - p
    n = torch.arange(N2, device=planes.device)
    corner = itl.to(torch.int64)
    cols = _pair_clamp(corner[:, 0, None] + n, width)  # (T, 16)
    rows = _pair_clamp(corner[:, 1, None] + n, height)
    flat = planes.reshape(planes.shape[0], -1)  # (C, H W)
    index = (rows[:, :, None] * width + cols[:, None, :]).reshape(1, -1)  # (1, T 256)
    windows = flat.index_select(1, index[0]).reshape(planes.shape[0], -1, N2, N2).transpose(0, 1)
    inside = (corner[:, 0] >= 0) & (corner[:, 0] + N2 <= width) & (corner[:, 1] >= 0) & (corner[:, 1] + N2 <= height)
    return windows, s, inside


def _half_sine(t: torch.Tensor) -> torch.Tensor:
    """``tables.half_sine``: w(t) = sin(pi (2t + 1) / 32)."""
    return torch.sin(math.pi * (2 * t + 1) / 32.0)


def _prerotation(windows: torch.Tensor, sx: torch.Tensor, sy: torch.Tensor) -> torch.Tensor:
    """Shifted window, fold, DTT-IV of ``windows (T, C, 16, 16)`` at residuals ``(T, 1)``: ``(T, C, 4, 8, 8)``
    (``reference.mclt_prerotation``)."""
    tb = _tables(windows.device, windows.dtype)
    n = torch.arange(N2, device=windows.device, dtype=windows.dtype)
    wx = _half_sine(n + sx[..., None])  # (T, 1, 16)
    wy = _half_sine(n + sy[..., None])
    xw = windows * wy[..., :, None] * wx[..., None, :]
    fold, dtt = tb["fold"], tb["dtt"]
    out = [dtt[q >> 1] @ (fold[q >> 1] @ xw @ fold[q & 1].T) @ dtt[q & 1].T for q in range(4)]
    return torch.stack(out, dim=-3)


def _rotate(f: torch.Tensor, sx: torch.Tensor, sy: torch.Tensor) -> torch.Tensor:
    """Phase rotation by the residual (§4), ``reference.rotate``: f ``(T, C, 4, 8, 8)``, s ``(T, 1)``."""
    omega = _tables(f.device, f.dtype)["omega"]
    bx = sx[..., None, None] * omega[None, :]  # (T, 1, 1, 8)
    by = sy[..., None, None] * omega[:, None]  # (T, 1, 8, 1)
    cc, sc, cs, ss = f.unbind(-3)
    cx, snx = torch.cos(bx), torch.sin(bx)
    cc, sc = cc * cx - sc * snx, cc * snx + sc * cx
    cs, ss = cs * cx - ss * snx, cs * snx + ss * cx
    cy, sny = torch.cos(by), torch.sin(by)
    cc, cs = cc * cy - cs * sny, cc * sny + cs * cy
    sc, ss = sc * cy - ss * sny, sc * sny + ss * cy
    return torch.stack([cc, sc, cs, ss], dim=-3)


def bmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Bicomplex product per frequency of ``(..., 4, 8, 8)`` tiles (``reference.bmul``)."""
    a0, a1, a2, a3 = a.unbind(-3)
    b0, b1, b2, b3 = b.unbind(-3)
    return torch.stack([a0 * b0 - a1 * b1 - a2 * b2 + a3 * b3, a0 * b1 + a1 * b0 - a2 * b3 - a3 * b2,
                        a0 * b2 + a2 * b0 - a1 * b3 - a3 * b1, a0 * b3 + a3 * b0 + a1 * b2 + a2 * b1], dim=-3)


def convert_tiles(planes: torch.Tensor, centres: torch.Tensor, kernels: torch.Tensor | None = None):
    """Frequency-domain tiles ``(T, C, 4, 8, 8)`` and ``inside (T,)`` of planes ``(C, H, W)`` at centres
    ``(T, 2)`` (x, y, that camera's pixels); optional CLT kernels broadcastable to ``(T, C, 4, 8, 8)``
    (``reference.convert_tiles``)."""
    windows, s, inside = extract_windows(planes, centres)
    sx, sy = s[:, 0, None], s[:, 1, None]  # (T, 1): broadcast over C
    f = _prerotation(windows, sx, sy)
    if kernels is not None:
        f = bmul(kernels, f)
    return _rotate(f, sx, sy), inside


def correlate_fd(first: torch.Tensor, second: torch.Tensor, *, colour_weights, fat_zero: float, sigma_rb: float,
                 sigma_corr: float) -> torch.Tensor:
    """Colour-weighted, fat-zero normalised, low-passed correlation spectrum ``(..., 4, 8, 8)`` of CLT tile pairs
    ``(..., C, 4, 8, 8)`` (C 1 or 3; ``reference.correlate_fd`` with every setting explicit)."""
    conj = torch.as_tensor([1.0, -1.0, -1.0, 1.0], dtype=first.dtype, device=first.device)[:, None, None]
    products = bmul(first * conj, second)
    if first.shape[-4] == 3:
        acc = colour_weights[0] * products[..., 0, :, :, :] + colour_weights[1] * products[..., 1, :, :, :]
        acc = acc * torch.as_tensor(tables.lpf(sigma_rb), dtype=acc.dtype, device=acc.device)
        acc = acc + colour_weights[2] * products[..., 2, :, :, :]
    else:
        acc = colour_weights[0] * products[..., 0, :, :, :]
    norm = torch.sqrt(fat_zero**2 + torch.sum(acc**2, dim=-3, keepdim=True))
    safe = torch.where(norm > 0, norm, torch.ones_like(norm))  # no 0/0 in the backward pass either
    acc = torch.where(norm > 0, acc / safe, torch.zeros_like(acc))
    return acc * torch.as_tensor(tables.lpf(sigma_corr), dtype=acc.dtype, device=acc.device)


def corr_to_pixels(x: torch.Tensor) -> torch.Tensor:
    """Correlation spectrum ``(..., 4, 8, 8)`` to the pixel-domain correlation ``(..., 15, 15)`` (§6.3)."""
    a = _tables(x.device, x.dtype)["lags"]
    return sum(a[q >> 1] @ x[..., q, :, :] @ a[q & 1].T for q in range(4))


def correlate(planes: torch.Tensor, centres: torch.Tensor, pairs, config) -> tuple[torch.Tensor, torch.Tensor]:
    """Pair correlations of one frame: planes ``(cams, C, H, W)``, centres ``(T, cams, 2)``, ``pairs`` ((a, b),
    ...), ``config`` a resolved ``CorrelationConfig`` for C colours. Returns ``(corr (T, P, 15, 15), inside (T,))``
    (inside: every camera's window lies in the image)."""
    cams = planes.shape[0]
    tiles, inside = zip(*(convert_tiles(planes[c], centres[:, c]) for c in range(cams)))
    first = torch.stack([tiles[a] for a, _ in pairs], dim=1)  # (T, P, C, 4, 8, 8)
    second = torch.stack([tiles[b] for _, b in pairs], dim=1)
    fd = correlate_fd(first, second, colour_weights=config.colour_weights, fat_zero=config.fat_zero,
                      sigma_rb=config.sigma_rb, sigma_corr=config.sigma_corr)
    return corr_to_pixels(fd), torch.stack(inside).all(dim=0)
