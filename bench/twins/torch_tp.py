"""Plain-PyTorch-ops float32 tile processor: the convert and correlate stages as ordinary torch tensor ops.

The same math as ``bench/twins/numpy_tp.py`` (and ``kernels/convert.py``, ``kernels/correlate.py``;
tile_processor.md §1.4, §3.1, §6.2, §6.3), written with batched matmuls over all tiles, so that one implementation
runs on CPU and CUDA tensors alike: everything happens on the device of the input tensors, with no host copies
inside (the small constant tables are built once per device and dtype with NumPy and cached: the colour masks and
the lag matrix from ``tpnet_gpu.operators``, the basis expansion, product signs and correlation weights from
``twins/common.py``). It is the "what a PyTorch user would write" peer of the Warp kernels in the benchmarks. Not
the oracle: that is ``tpnet_gpu.reference`` (float64), which this module deliberately does not import
(tests/bench/twins/test_torch_tp.py checks both). No aberration kernels, no validity masks: inputs must be finite.

Convert, per camera (tiles in chunks):
    p = centre - 8, itl = floor(p + 0.5), s = itl - p
    x = 16x16 window at (itl_y, itl_x), every pixel index through the pair-preserving clamp (one gather)
    x_c = x * mask_c (zero-fill Bayer mask of colour c = R, B, G, green scaled by 0.5; mono: no mask)
    [F_CC F_SC; F_CS F_SS] = Bv^T @ x_c @ Bh   (Bv, Bh: (16, [phi, k]) per-tile bases, phi = cos, sin)
with the closed-form bases B[n, (phi, k)] = 1/2 w(n + s) phi(omega_k (n + s + 4.5)) of every tile from one GEMM
(features of cos/sin(pi s / 16) and cos/sin(omega_k s) times a fixed expansion; see twins.common.basis_expansion).

Correlate, per pair (tiles in chunks): P_ij = sum_c weight_c A_ci B_cj per frequency (weights w_R, w_B times
L(sigma_rb), w_G), X = signs @ P (the conjugate bicomplex product, §6.2), the fat-zero normalisation, L(sigma_corr);
then one GEMM for all pairs with the fixed (256 -> 225) frequency-to-lag matrix (§6.3).

Tiles are processed in chunks (``chunk`` tiles at a time; default 1024 on CPU, where the work buffers then stay in
cache, and all tiles at once on CUDA). Work buffers are allocated once per call and written with ``out=``: on CPU,
torch hands large temporaries back to the OS, and every fresh one costs a page fault per 4 KiB (and batched matmuls
into non-contiguous outputs fall back to a per-matrix loop).
"""

from __future__ import annotations

import numpy as np
import torch

from tpnet_gpu import operators, tables
from tpnet_gpu.layout import HALF_TILE, NET_CROP

from tpnet_gpu.bench.twins.common import N, SIDE, WIN, basis_expansion, conj_product_signs, correlation_weights

CPU_CHUNK = 1024  # tiles per chunk on CPU: the work buffers (~3 MB each) stay in cache

__all__ = ["torch_convert", "torch_correlate", "torch_layers"]

_CACHE: dict = {}


def _constant(name: str, make, device: torch.device, dtype=torch.float32) -> torch.Tensor:
    """A constant table ``make()`` (NumPy) on ``device``, built and uploaded once per (name, device, dtype)."""
    key = (name, str(device), dtype)
    if key not in _CACHE:
        _CACHE[key] = torch.as_tensor(np.ascontiguousarray(make()), dtype=dtype, device=device)
    return _CACHE[key]


def _chunk_size(chunk: int | None, device: torch.device, tiles: int) -> int:
    if chunk is None:
        chunk = CPU_CHUNK if device.type == "cpu" else tiles
    if chunk < 1:
        raise ValueError(f"chunk: expected a positive number of tiles, got {chunk}")
    return max(1, min(chunk, tiles))


# --- convert ----------------------------------------------------------------------------------------------------


def _basis(s: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
    """Per-tile forward bases into ``out (T, 16, 16)`` [n, (phi, k)] of residuals ``s (T,)``: one GEMM (see module
    doc)."""
    omega = _constant("omega", tables.omega, s.device)
    expansion = _constant("basis_expansion", basis_expansion, s.device)
    beta = (s * np.float32(np.pi / 16))[:, None]  # (T, 1)
    gamma = s[:, None] * omega[None, :]  # (T, 8)
    cb, sb, cg, sg = torch.cos(beta), torch.sin(beta), torch.cos(gamma), torch.sin(gamma)
    features = torch.cat([cb * cg, cb * sg, sb * cg, sb * sg], dim=1)  # (T, 32)
    torch.mm(features, expansion, out=out.view(-1, WIN * 2 * N))
    return out


def _pair_clamp(q: torch.Tensor, size: int) -> torch.Tensor:
    """Pair-preserving clamp: q < 0 -> q & 1, q >= size -> size - 2 + (q & 1)."""
    return torch.where(q < 0, q & 1, torch.where(q >= size, size - 2 + (q & 1), q))


def torch_convert(frames, centres, cfa: str | None = tables.DEFAULT_CFA, *, chunk: int | None = None) -> torch.Tensor:
    """CLT tiles ``(tiles, cams, colours, 4, 8, 8)`` float32 of raw frames at per-camera tile centres.

    frames: ``(cams, H, W)`` raw Bayer mosaics in ``cfa`` (or mono for ``cfa=None``), a tensor (its device is used)
    or array; converted to float32 once if needed. centres: ``(tiles, cams, 2)`` (x, y) in pixels, finite (moved to
    the frames' device if needed). Colours R, B, G (or 1 for mono); quadrants CC, SC, CS, SS.

    The masked windows are laid out ``(t, row, colour, col)`` so that both transforms are plain batched matmuls
    without broadcast copies: ``Bv^T @ x`` over all colours' columns at once, then ``@ Bh`` over all rows.
    """
    frames = torch.as_tensor(frames)
    frames = frames.to(torch.float32) if frames.dtype != torch.float32 else frames
    device = frames.device
    centres = torch.as_tensor(centres).to(device=device, dtype=torch.float32)
    if frames.dim() != 3 or centres.dim() != 3 or tuple(centres.shape[1:]) != (frames.shape[0], 2):
        raise ValueError(f"frames, centres: expected (cams, H, W) and (tiles, cams, 2), got "
                         f"{tuple(frames.shape)} and {tuple(centres.shape)}")
    cams, height, width = frames.shape
    tiles = centres.shape[0]
    masks = _constant(f"masks_{cfa}", lambda: operators.colour_masks(cfa).transpose(0, 2, 1, 3),
                      device)  # (4, 16, C, 16)
    colours = masks.shape[2]
    clt = torch.empty((tiles, cams, colours, 4, N, N), dtype=torch.float32, device=device)
    if tiles == 0:
        return clt
    flat = frames.reshape(cams, height * width)
    ramp = torch.arange(WIN, device=device)
    step = _chunk_size(chunk, device, tiles)
    f32 = dict(dtype=torch.float32, device=device)
    index_buf = torch.empty((step, WIN, WIN), dtype=torch.int64, device=device)  # flat pixel index [row, col]
    windows_buf = torch.empty((step, WIN, WIN), **f32)
    x_buf = torch.empty((step, WIN, colours, WIN), **f32)  # masked windows [row, colour, col]
    bh_buf = torch.empty((step, WIN, 2 * N), **f32)  # [col, (phi_x, kx)]
    bv_buf = torch.empty((step, WIN, 2 * N), **f32)  # [row, (phi_y, ky)]
    v_buf = torch.empty((step, 2 * N, colours * WIN), **f32)  # [(phi_y, ky), (colour, col)]
    full_buf = torch.empty((step, 2 * N * colours, 2 * N), **f32)  # [(phi_y, ky, colour), (phi_x, kx)]
    for start in range(0, tiles, step):
        part = slice(start, min(start + step, tiles))
        t = part.stop - part.start
        p = centres[part] - np.float32(HALF_TILE)  # (t, cams, 2)
        itl_f = torch.floor(p + np.float32(0.5))
        s = itl_f - p  # float32 residuals, as in the kernels
        itl = itl_f.to(torch.int64)
        index, windows, x = index_buf[:t], windows_buf[:t], x_buf[:t]
        for cam in range(cams):
            rows = _pair_clamp(itl[:, cam, 1, None] + ramp, height)  # (t, 16)
            cols = _pair_clamp(itl[:, cam, 0, None] + ramp, width)
            torch.add((rows * width)[:, :, None], cols[:, None, :], out=index)
            torch.take(flat[cam], index, out=windows)  # (t, 16, 16): one gather
            parity = 2 * (itl[:, cam, 1] & 1) + (itl[:, cam, 0] & 1)
            torch.index_select(masks, 0, parity, out=x)
            x.mul_(windows[:, :, None])  # (t, row, C, col)
            bh = _basis(s[:, cam, 0], out=bh_buf[:t])
            bv = _basis(s[:, cam, 1], out=bv_buf[:t])
            v = torch.bmm(bv.transpose(1, 2), x.view(t, WIN, colours * WIN), out=v_buf[:t])
            full = torch.bmm(v.view(t, 2 * N * colours, WIN), bh, out=full_buf[:t])
            # Quadrant q = 2 phi_y + phi_x: CC, SC, CS, SS.
            out = clt[part, cam].view(t, colours, 2, 2, N, N)  # [colour, phi_y, phi_x, ky, kx]
            out.copy_(full.view(t, 2, N, colours, 2, N).permute(0, 3, 1, 4, 2, 5))
    return clt


# --- correlate --------------------------------------------------------------------------------------------------


def torch_correlate(
    clt,
    pairs=tables.QUAD_PAIRS,
    colour_weights=None,
    fat_zero: float = tables.CORR_FAT_ZERO,
    sigma_rb: float = tables.CORR_SIGMA_RB,
    sigma_corr: float | None = None,
    *,
    chunk: int | None = None,
) -> torch.Tensor:
    """Pixel-domain pair correlations ``(tiles, len(pairs), 15, 15)`` float32 of CLT tiles, on ``clt``'s device.

    clt: ``(tiles, cams, colours, 4, 8, 8)`` (colours 3 = R, B, G or 1 = mono); pairs: (first, second) cameras.
    Defaults as the GPU path: weights (0.25, 0.25, 0.5) or (1,), sigma_corr 0.9 or 0.15 (mono); sigmas are
    variances (tables.lpf). Row = vertical lag + 7, column = horizontal lag + 7.
    """
    clt = torch.as_tensor(clt)
    clt = clt.to(torch.float32) if clt.dtype != torch.float32 else clt
    if clt.dim() != 6 or clt.shape[2] not in (1, 3) or tuple(clt.shape[3:]) != (4, N, N):
        raise ValueError(f"clt: expected (tiles, cams, 1 or 3, 4, 8, 8), got {tuple(clt.shape)}")
    tiles, _, colours = clt.shape[:3]
    device = clt.device
    pairs = [(int(a), int(b)) for a, b in pairs]
    # (C, 64) and (64,): X = (w_R P_R + w_B P_B) L_rb + w_G P_G, then L_corr (defaults resolved and checked there)
    key = (colours, None if colour_weights is None else tuple(float(w) for w in colour_weights), float(sigma_rb),
           None if sigma_corr is None else float(sigma_corr))
    weights = _constant(f"weights_{key}", lambda: correlation_weights(colours, colour_weights, sigma_rb, sigma_corr)[0],
                        device)
    lpf_corr = _constant(f"lpf_{key}", lambda: correlation_weights(colours, colour_weights, sigma_rb, sigma_corr)[1],
                         device)
    signs = _constant("signs", conj_product_signs, device)
    to_lags = _constant("lags", operators.lag_matrix, device)
    fz2 = float(np.float32(fat_zero) ** 2)
    npairs = len(pairs)
    corr = torch.empty((tiles, npairs, SIDE * SIDE), dtype=torch.float32, device=device)
    if tiles == 0:
        return corr.view(tiles, npairs, SIDE, SIDE)
    step = _chunk_size(chunk, device, tiles)
    cams = clt.shape[1]
    f32 = dict(dtype=torch.float32, device=device)
    # Work buffers, reused for every chunk and pair (fresh large temporaries cost a page fault per 4 KiB on CPU).
    weighted_buf = torch.empty((step, cams, colours, 4, N * N), **f32)  # weight_c A_ci of every camera
    products_buf = torch.empty((step, 4, 4, N * N), **f32)  # [i, j, f]: sum_c weight_c A_ci B_cj
    x_buf = torch.empty((step, 4, N * N), **f32)  # X [q, f]
    norm_buf = torch.empty((step, N * N), **f32)
    spectra_buf = torch.empty((step, npairs, 4, N * N), **f32)  # L_corr X / |X| of every pair
    for start in range(0, tiles, step):
        part = slice(start, min(start + step, tiles))
        t = part.stop - part.start
        block = clt[part].reshape(t, cams, colours, 4, N * N)
        weighted = torch.mul(block, weights[:, None], out=weighted_buf[:t])
        products, x, norm2, spectra = products_buf[:t], x_buf[:t], norm_buf[:t], spectra_buf[:t]
        for p, (a, b) in enumerate(pairs):
            first, second = weighted[:, a], block[:, b]  # (t, C, 4, 64)
            torch.mul(first[:, 0, :, None], second[:, 0, None], out=products)
            for c in range(1, colours):
                products.addcmul_(first[:, c, :, None], second[:, c, None])
            torch.matmul(signs, products.view(t, 16, N * N), out=x)  # X = sum_c weight_c conj(A_c) B_c
            torch.sum(x * x, dim=1, out=norm2)
            norm2 += fz2
            scale = torch.where(norm2 > 0, lpf_corr * torch.rsqrt(norm2), torch.zeros_like(norm2))  # 0: |X| = fz = 0
            torch.mul(x, scale[:, None], out=spectra[:, p])  # L_corr X / |X|
        torch.mm(spectra.view(t * npairs, 4 * N * N), to_lags, out=corr[part].view(t * npairs, SIDE * SIDE))
    return corr.view(tiles, npairs, SIDE, SIDE)


# --- network layers ---------------------------------------------------------------------------------------------
def torch_layers(corr, offset: float = tables.NET_CORR_OFFSET) -> torch.Tensor:
    """The network's 4 correlation layers ``(tiles, 4, 9, 9)`` from the quad's 6 pair correlations.

    corr: ``(tiles, 6, 15, 15)`` in the order of ``tables.QUAD_PAIRS``. Layers [hor, vert, diag-main, diag-other]
    = [combine(pair 0, pair 1), combine(pair 2, pair 3), pair 4, pair 5], centre 9x9 crops, with
    combine(a, b) = sqrt((a + o)(b + o)) - o where a > 0 and b > 0, else 0 (o = ``offset``; o < 0: (a + b) / 2),
    as the processor's ``network_layers`` kernel (network.md §1).
    """
    corr = torch.as_tensor(corr)
    if corr.dim() != 4 or tuple(corr.shape[1:]) != (len(tables.QUAD_PAIRS), SIDE, SIDE):
        raise ValueError(f"corr: expected (tiles, 6, {SIDE}, {SIDE}) quad pair correlations, got {tuple(corr.shape)}")
    c = corr[:, :, NET_CROP : SIDE - NET_CROP, NET_CROP : SIDE - NET_CROP].to(torch.float32)  # (tiles, 6, 9, 9)
    a, b = c[:, 0:4:2], c[:, 1:4:2]  # (pair 0, pair 2) and (pair 1, pair 3)
    if offset < 0:
        combined = 0.5 * (a + b)
    else:
        product = ((a + offset) * (b + offset)).clamp_min(0.0)
        combined = torch.where((a > 0) & (b > 0), torch.sqrt(product) - offset, torch.zeros_like(a))
    return torch.cat([combined, c[:, 4:6]], dim=1)
