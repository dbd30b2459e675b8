"""Per-pixel left-right check, background fill of what it rejects, and tile answers from the checked pixels
(disparity.md §10).

A tile answer is one number for a 16x16 window; at a depth edge or next to a half-occlusion no single surface's
disparity is the window's. The per-pixel maps of both views (``per_pixel``, each from its own engine's tile
answers) say more: a pixel of the reference whose match in the other view answers the same disparity back
(within ``LEFT_RIGHT_PX``) is *measured*; the others are half-occluded or mismatched. The rejected pixels take
the background's disparity (the smaller of the nearest measured values either side along the baseline: a
half-occluded pixel lies beside the nearer surface that hides it, on the far surface), so the map is dense.

Each tile then answers the half-sine-weighted mean of that map over its window - where measured pixels hold at
least ``MIN_MEASURED`` of the window's weight; elsewhere the engine's answer stands - and its confidence is the
share of the window's weight whose measured pixels agree with the answer within ``AGREE_PX``: how much of the
window backs it. A tile under ``MIN_SUPPORT`` has no value by default. On the six real pairs of
``../shared/realdata`` this ranking leaves 9.4 % of tiles > 1 px off at OpenCV SGBM's coverage (SGBM 15.5 %;
the tile cross-check's ranking 17.1 %), docs/results.md §2.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu import tables
from tpnet_gpu.layout import TILE_SIZE, TILE_STRIDE

LEFT_RIGHT_PX = 1.0  # px: a pixel whose match answers back further than this is not measured
AGREE_PX = 1.0  # px: a measured pixel this close to the tile's answer backs it
MIN_MEASURED = 0.2  # share of a window's weight: measured pixels below this leave the engine's answer
MIN_SUPPORT = 0.02  # share of a window's weight backing the answer: a tile below this has no value by default
# (256,) the tile window's weights, row-major: the processor's half-sine in each direction
WINDOW = np.outer(tables.half_sine(np.arange(TILE_SIZE)), tables.half_sine(np.arange(TILE_SIZE))).reshape(-1)


def left_right(pixels: torch.Tensor, other: torch.Tensor, offset, tol: float = LEFT_RIGHT_PX) -> torch.Tensor:
    """``(h, w)`` bool: reference pixel (x, y) with disparity d = ``pixels[y, x]`` is measured when the other
    view's per-pixel disparity ``other (h, w)`` at its match (x - d ox, y - d oy), the nearest pixel, lies within
    ``tol`` of d; ``offset (ox, oy)`` is the other camera's, baseline units. False where either is NaN or the
    match leaves the image."""
    h, w = pixels.shape
    ox, oy = (float(v) for v in offset)
    d = torch.nan_to_num(pixels, nan=0.0)
    xs = torch.round(torch.arange(w, device=pixels.device, dtype=pixels.dtype)[None, :] - d * ox)
    ys = torch.round(torch.arange(h, device=pixels.device, dtype=pixels.dtype)[:, None] - d * oy)
    inside = torch.isfinite(pixels) & (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    index = (ys.clamp(0, h - 1) * w + xs.clamp(0, w - 1)).long()
    back = other.reshape(-1)[index.reshape(-1)].reshape(h, w)
    return inside & ((back - pixels).abs() <= tol)  # a NaN back compares False


def fill_background(pixels: torch.Tensor, offset) -> torch.Tensor:
    """``(h, w)``: ``pixels`` with each NaN replaced by the smaller of the nearest finite values before and after
    it along the baseline (rows for a baseline nearer horizontal, ``offset (ox, oy)``, columns otherwise); NaN
    where its line has none."""
    ox, oy = (float(v) for v in offset)
    lines = pixels if abs(ox) >= abs(oy) else pixels.t()
    n = lines.shape[1]
    finite = torch.isfinite(lines)
    index = torch.arange(n, device=lines.device).expand_as(lines)
    before = torch.where(finite, index, torch.full_like(index, -1)).cummax(dim=1).values
    after = torch.where(finite, index, torch.full_like(index, n)).flip(1).cummin(dim=1).values.flip(1)
    inf = torch.full_like(lines, float("inf"))
    left = torch.where(before >= 0, lines.gather(1, before.clamp(0, n - 1)), inf)
    right = torch.where(after < n, lines.gather(1, after.clamp(0, n - 1)), inf)
    nearest = torch.minimum(left, right)
    filled = torch.where(finite, lines, torch.where(torch.isfinite(nearest), nearest, torch.full_like(lines, float("nan"))))
    return filled if abs(ox) >= abs(oy) else filled.t()


def _windows(image: torch.Tensor) -> torch.Tensor:
    """``(tiles_y, tiles_x, 256)`` each tile's 16x16 window of ``image (8 tiles_y, 8 tiles_x)`` (tile t's window
    starts at 8 t - 4; NaN beyond the image)."""
    h, w = image.shape
    pad = (TILE_SIZE - TILE_STRIDE) // 2
    padded = F.pad(image[None, None], (pad,) * 4, value=float("nan"))
    cols = F.unfold(padded, TILE_SIZE, stride=TILE_STRIDE)[0]  # (256, tiles)
    return cols.t().reshape(h // TILE_STRIDE, w // TILE_STRIDE, TILE_SIZE * TILE_SIZE)


def tile_answers(filled: torch.Tensor, measured: torch.Tensor, fallback: torch.Tensor) -> tuple[torch.Tensor,
                                                                                                  torch.Tensor]:
    """Tile answers from the checked per-pixel map (module docstring). ``filled (H, W)`` the background-filled
    map (NaN = none), ``measured (H, W)`` bool the pixels the left-right check kept, ``fallback (H / 8, W / 8)``
    the engine's answers (H, W multiples of 8). Returns ``(disparity, confidence)``, each ``(H / 8, W / 8)``:
    the window's weighted mean of ``filled`` where measured pixels hold ``MIN_MEASURED`` of its weight, else
    ``fallback``; and the share of the window's weight whose measured pixels lie within ``AGREE_PX`` of that
    answer (0 where the answer is NaN)."""
    weight = torch.as_tensor(WINDOW, device=filled.device, dtype=filled.dtype)
    total = weight.sum()
    values = _windows(filled)
    known = torch.isfinite(values)
    checked = _windows(torch.where(measured, filled, torch.full_like(filled, float("nan"))))
    is_checked = torch.isfinite(checked)
    known_weight = (known * weight).sum(-1)
    mean = (torch.where(known, values, torch.zeros_like(values)) * weight).sum(-1) / known_weight.clamp_min(1e-12)
    enough = (is_checked * weight).sum(-1) >= MIN_MEASURED * total
    answer = torch.where(enough & (known_weight > 0), mean, fallback)
    backs = is_checked & ((checked - answer[..., None]).abs() <= AGREE_PX)
    confidence = torch.where(torch.isfinite(answer), (backs * weight).sum(-1) / total, torch.zeros_like(answer))
    return answer, confidence
