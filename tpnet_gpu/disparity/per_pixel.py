"""Per-pixel disparity from the tile answers of a rectified pair (disparity.md §9).

A tile answer holds for its 16x16 window; at a depth edge the window's stronger surface wins and spreads over the
whole tile (the "fattened" foreground). Each pixel therefore chooses among the answers of the 3x3 tiles around
its 8x8 cell (and their bilinear blend, for slanted surfaces) the one whose match is best in a small window
around the pixel: the zero-mean normalised cross-correlation (ZNCC, blind to gain and offset between the
cameras) of the reference image with the other image moved by that answer, over ``RADIUS``. So depth edges move
onto the image's edges, within the candidates the tiles offer; where no candidate matches (ZNCC below
``MIN_ZNCC``) or the match leaves the other image, the pixel has no value (NaN).

The other camera sees the reference pixel (x, y) at (x - d * ox, y - d * oy), ``(ox, oy)`` its offset from the
reference camera in baseline units (``checks`` module): (1, 0) for the right image of a pair seen from the
left.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from tpnet_gpu.layout import TILE_STRIDE

RADIUS = 3  # px: the ZNCC window is (2 RADIUS + 1)^2 (7x7)
MIN_ZNCC = 0.3  # a pixel whose best candidate correlates less has no value
FLAT_VARIANCE = 1e-6  # relative to the image's variance: a window this flat has no ZNCC (it is 0 there)


class _BoxMeans:
    """Window means of up to 4 images at once, by running sums in one buffer it owns: ``(4, h + 2 radius + 1,
    w + 2 radius + 1)``, a zero first row and column, then each image edge-replicated by ``radius``. The
    callers write images into ``interior(i)`` and read ``means(n)``: the buffers are made once per
    ``per_pixel`` call, not once per candidate (new padded tensors for every candidate's sums were most of the
    40 % of the step this and ``_Warp`` saved: docs/results.md §12)."""

    def __init__(self, shape: tuple[int, int], radius: int, device):
        h, w = shape
        self.h, self.w, self.r = h, w, radius
        k = 2 * radius + 1
        self.k = k
        self.sums = torch.zeros((4, h + k, w + k), device=device)  # rows and columns of running sums
        self.rows = torch.empty((4, h + k, w), device=device)
        self.out = torch.empty((4, h, w), device=device)

    def interior(self, i: int) -> torch.Tensor:
        """``(h, w)`` view where image ``i`` goes."""
        r = self.r
        return self.sums[i, 1 + r: 1 + r + self.h, 1 + r: 1 + r + self.w]

    def means(self, n: int) -> torch.Tensor:
        """``(n, h, w)`` the means of images ``0..n-1`` over each pixel's (2 radius + 1)^2 window
        (edge-replicated), as differences of running sums along each axis (2.8x faster than ``avg_pool2d`` for a
        7x7 window on 4 VGA images). Float32 running sums lose ~1e-7 of a row's sum: the caller centres its
        images (``per_pixel``). The view is overwritten by the next call."""
        r, h, w, k = self.r, self.h, self.w, self.k
        s = self.sums[:n]
        s[:, 1: 1 + r, 1 + r: 1 + r + w] = s[:, 1 + r: 2 + r, 1 + r: 1 + r + w]  # replicate: top, bottom rows
        s[:, 1 + r + h:, 1 + r: 1 + r + w] = s[:, r + h: 1 + r + h, 1 + r: 1 + r + w]
        s[:, 1:, 1: 1 + r] = s[:, 1:, 1 + r: 2 + r]  # then left and right columns, corners included
        s[:, 1:, 1 + r + w:] = s[:, 1:, r + w: 1 + r + w]
        s.cumsum_(-1)  # row 0 and column 0 stay zero: the sums' leading zeros
        rows = torch.sub(s[..., k:], s[..., :-k], out=self.rows[:n])
        rows.cumsum_(-2)
        return torch.sub(rows[:, k:], rows[:, :-k], out=self.out[:n]).div_(k * k)


def cell_field(tiles: torch.Tensor, shape: tuple[int, int], dy: int, dx: int) -> torch.Tensor:
    """``(h, w)``: each pixel gets the answer of the tile ``(dy, dx)`` from its own (pixel (x, y) is in tile
    (x // 8, y // 8)'s centre cell); NaN beyond the grid."""
    ty, tx = tiles.shape
    padded = F.pad(tiles[None, None], (1, 1, 1, 1), value=float("nan"))[0, 0]
    h, w = shape
    rows = torch.clamp(torch.arange(h, device=tiles.device) // TILE_STRIDE, max=ty - 1) + 1 + dy
    cols = torch.clamp(torch.arange(w, device=tiles.device) // TILE_STRIDE, max=tx - 1) + 1 + dx
    return padded[rows][:, cols]


def blend_field(tiles: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """``(h, w)`` bilinear interpolation of the tile answers between tile centres (8 t + 4), NaN-aware: a NaN
    tile's weight goes to its finite neighbours; NaN where all four are NaN."""
    finite = torch.isfinite(tiles)
    stack = torch.stack([torch.where(finite, tiles, torch.zeros_like(tiles)), finite.to(tiles.dtype)])[None]
    h, w = shape
    # pixel centre p + 0.5 in tile-centre units: (p + 0.5 - 4) / 8, as align_corners=True coordinates
    ty, tx = tiles.shape
    ys = (torch.arange(h, device=tiles.device, dtype=tiles.dtype) + 0.5 - TILE_STRIDE / 2) / TILE_STRIDE
    xs = (torch.arange(w, device=tiles.device, dtype=tiles.dtype) + 0.5 - TILE_STRIDE / 2) / TILE_STRIDE
    gy = (2 * ys / max(ty - 1, 1) - 1).clamp(-1, 1)
    gx = (2 * xs / max(tx - 1, 1) - 1).clamp(-1, 1)
    grid = torch.stack(torch.meshgrid(gx, gy, indexing="xy"), dim=-1)[None]
    sums = F.grid_sample(stack, grid, mode="bilinear", align_corners=True)[0]
    return torch.where(sums[1] > 1e-6, sums[0] / sums[1].clamp_min(1e-6), torch.full_like(sums[0], float("nan")))


def warp(other: torch.Tensor, disparity: torch.Tensor, offset) -> torch.Tensor:
    """``(h, w)`` ``other`` sampled at (x - d * ox, y - d * oy), bilinear; NaN where that leaves the image or d
    is NaN."""
    return _Warp(other, offset)(disparity)


class _Warp:
    """``warp`` of one image by many disparity maps: the grid of the axis the offset does not move (a pair's rows)
    and the sampling grid's buffer made once; the range tests stand in for ``isfinite`` (NaN fails them)."""

    def __init__(self, other: torch.Tensor, offset):
        h, w = other.shape
        self.other = other[None, None]
        self.offset = tuple(float(v) for v in offset)
        self.lengths = (w, h)  # along x, along y
        self.grid = torch.empty((1, h, w, 2), device=other.device, dtype=other.dtype)
        self.index = (torch.arange(w, device=other.device, dtype=other.dtype)[None, :],
                      torch.arange(h, device=other.device, dtype=other.dtype)[:, None])
        for axis, (o, n) in enumerate(zip(self.offset, self.lengths)):
            if o == 0.0:  # at the pixel's own row (column) wherever d is finite
                self.grid[0, ..., axis] = 2 * self.index[axis] / max(n - 1, 1) - 1

    def __call__(self, disparity: torch.Tensor) -> torch.Tensor:
        inside = None  # a NaN or infinite d, or coordinate, fails the range check
        for axis, (o, n) in enumerate(zip(self.offset, self.lengths)):
            if o == 0.0:
                continue
            at = self.index[axis] - o * disparity
            within = (at >= 0) & (at <= n - 1)
            inside = within if inside is None else inside & within
            self.grid[0, ..., axis] = 2 * torch.nan_to_num(at, nan=0.0) / max(n - 1, 1) - 1
        if inside is None:  # a camera at the reference's own place
            inside = torch.isfinite(disparity)
        sampled = F.grid_sample(self.other, self.grid, mode="bilinear", align_corners=True,
                                padding_mode="border")[0, 0]
        return torch.where(inside, sampled, torch.full_like(sampled, float("nan")))


class _Windows:
    """The ZNCC of the reference image with moved images: the reference's window means made once, and the
    window sums' buffers (``_BoxMeans``) reused for every candidate."""

    def __init__(self, reference: torch.Tensor, radius: int):
        self.radius = radius
        self.ref = reference
        self.box = _BoxMeans(tuple(reference.shape), radius, reference.device)
        self.box.interior(0).copy_(reference)
        torch.mul(reference, reference, out=self.box.interior(1))
        self.mean, square = self.box.means(2).clone()
        self.var = (square - self.mean ** 2).clamp_min(0)
        self.floor = FLAT_VARIANCE * float(reference.var()) + 1e-12

    def zncc(self, moved: torch.Tensor) -> torch.Tensor:
        """``(h, w)`` ZNCC of the reference with ``moved`` over each pixel's window; -1 where ``moved`` has NaN
        in the window."""
        box = self.box
        m = torch.nan_to_num(moved, nan=0.0, out=box.interior(1))
        box.interior(0).copy_(torch.isnan(moved))  # the NaN count is exact: small integers
        torch.mul(m, m, out=box.interior(2))
        torch.mul(self.ref, m, out=box.interior(3))
        nans, mean, square, cross = box.means(4)  # one pass over the four window sums
        var = (square - mean ** 2).clamp_min_(0)
        cov = cross - self.mean * mean
        z = cov.div_(torch.sqrt(self.var * var).clamp_min_(self.floor))
        return z.masked_fill_(nans > 0.5 / (2 * self.radius + 1) ** 2, -1.0)


def per_pixel(reference: torch.Tensor, other: torch.Tensor, tiles: torch.Tensor, *, offset=(1.0, 0.0),
              radius: int = RADIUS, min_zncc: float = MIN_ZNCC) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-pixel disparity of ``reference (h, w)`` (see the module docstring) from the tile answers
    ``tiles (ceil(h / 8), ceil(w / 8))`` px (NaN = none) against ``other (h, w)``, the camera at ``offset``.

    Returns ``(disparity, zncc)``, each ``(h, w)`` float32: the chosen answer (NaN where no candidate reached
    ``min_zncc`` or all were NaN) and its ZNCC (-1 where none)."""
    level = reference.float().mean()  # both centred on it: ZNCC ignores offsets, and the window sums keep
    reference = reference.float() - level  # their precision (``_BoxMeans``)
    other = other.float() - level
    tiles = tiles.float()
    shape = tuple(reference.shape)
    windows = _Windows(reference, radius)
    moving = _Warp(other, offset)
    best = torch.full(shape, -1.0, device=reference.device)
    chosen = torch.full(shape, float("nan"), device=reference.device)
    candidates = [blend_field(tiles, shape)] + [
        cell_field(tiles, shape, dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    for field in candidates:  # the blend first: a plain cell answer must beat it to win
        z = windows.zncc(moving(field))
        better = z > best  # a NaN field moves no pixel: its windows' ZNCC is -1, never above the best
        torch.where(better, z, best, out=best)
        torch.where(better, field, chosen, out=chosen)
    chosen = torch.where(best >= min_zncc, chosen, torch.full_like(chosen, float("nan")))
    return chosen, best
