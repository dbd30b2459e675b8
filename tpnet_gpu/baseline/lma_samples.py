"""Samples of the LMA peak fit: the settings, the two pair groups and the convex sample masks
(geometry_and_lma.md B.4, C.4, C.7). Float64 NumPy, vectorised over tiles; the fit itself is ``lma.py``.

Conventions as in ``tpnet_gpu.baseline.lma`` (rows = vertical lag + 7, pair order B.1, diagonal samples in
rotated coordinates).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

CORR_SIZE = 15  # side of a pair correlation tile, lags -7..7
CORR_CENTRE = 7
NUM_PAIRS = 6
ORTHO_PAIRS = (0, 1, 2, 3)
TRANSPOSED_PAIRS = (2, 3)  # vertical pairs: transpose so the disparity axis is +x
DIAG_PAIRS = (4, 5)
FLIPPED_PAIRS = (5,)  # diag-other: rows flipped (row -> 14 - row) onto the main diagonal
NUM_PARS = 5  # x0, Wm, Wxy, A_ortho, A_diag (Wyd is fixed at 0, lma_adjust_wy = false)
X0, WM, WXY, A_ORTHO, A_DIAG = range(NUM_PARS)
GROUP_SCALES = (1.0, np.sqrt(2.0))  # s of the model per group: ortho, diagonal
SINGULAR_RCOND = 1e-13  # reciprocal condition (unit-diagonal scaled) below which a step matrix is singular
WIDTH_FLOOR = 0.02  # floor of the neighbour / centre ratios that measure a peak's width (sigma >= 0.36 px)
WIDEN_RADIUS = 4  # half-size of the widening low-pass kernel [px] (3.3 sigma at the default peak_sigma 1.2)


@dataclass(frozen=True)
class LmaParams:
    """LMA defaults (C.7, the original's ImageDttParameters). Names follow C.7; units in the comments."""

    half_width: float = 2.0  # lma_half_width: initial and regularisation target of Wm [px]
    cost_wy: float = 0.1  # lma_cost_wy: weight of the residual (Wm - half_width), before normalisation
    cost_wxy: float = 0.1  # lma_cost_wxy: weight of the residual (Wxy - 0), before normalisation
    lambda_initial: float = 0.1  # lma_lambda_initial
    lambda_good: float = 0.5  # lma_lambda_scale_good: lambda factor after an accepted step
    lambda_bad: float = 8.0  # lma_lambda_scale_bad: lambda factor after a rejected step
    lambda_max: float = 100.0  # lma_lambda_max: give up when lambda exceeds it
    rms_diff: float = 0.001  # lma_rms_diff: finish when an accepted step lowers the cost by less (relative)
    num_iter: int = 20  # lma_num_iter: maximal number of LM steps
    cnvx_weight: float = 0.5  # cnvx_weight: mask weight of selected non-convex cells (and the 3x3 fill)
    vasw_pwr: float = 2.0  # ortho_vasw_pwr: sample weight ~ |value| ** vasw_pwr
    hwnd: int = 4  # cnvx_hwnd_size: half-size of the sample box [px], 9x9 for 4
    # This project's addition (C.4 "Peak widening"): peaks of a Gaussian-equivalent sigma [px] below
    # peak_sigma_min are low-passed to peak_sigma before sampling; peak_sigma_min 0 turns it off (the original).
    peak_sigma: float = 1.2
    peak_sigma_min: float = 1.1

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("num_iter", "hwnd"):
                if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                    raise ValueError(f"LmaParams.{f.name}: expected an integer >= 1, got {value!r}")
            elif not np.isfinite(value):
                raise ValueError(f"LmaParams.{f.name}: expected a finite number, got {value!r}")
        if self.hwnd > CORR_CENTRE:
            raise ValueError(f"LmaParams.hwnd: expected <= {CORR_CENTRE}, got {self.hwnd}")
        for name in ("half_width", "lambda_initial", "lambda_good", "lambda_bad", "lambda_max"):
            if getattr(self, name) <= 0:
                raise ValueError(f"LmaParams.{name}: expected > 0, got {getattr(self, name)!r}")
        for name in ("cost_wy", "cost_wxy", "rms_diff", "cnvx_weight", "vasw_pwr", "peak_sigma", "peak_sigma_min"):
            if getattr(self, name) < 0:
                raise ValueError(f"LmaParams.{name}: expected >= 0, got {getattr(self, name)!r}")
        if self.peak_sigma_min > self.peak_sigma:
            raise ValueError(f"LmaParams.peak_sigma_min: expected <= peak_sigma {self.peak_sigma!r}, "
                             f"got {self.peak_sigma_min!r}")


def combine_groups(corr, pairs_mask=None):
    """Average the 6 pair correlations into the ortho and diagonal LMA groups (B.4).

    Parameters
    ----------
    corr : array_like, ``(tiles, 6, 15, 15)``
        Pair correlations in the B.1 pair order; row = y lag + 7, column = x lag + 7.
    pairs_mask : array_like of bool, ``(6,)`` or ``(tiles, 6)``, optional
        Pairs to use (default all). A pair whose 15x15 is entirely NaN counts as missing for that tile.

    Returns
    -------
    ortho, diag : ``(tiles, 15, 15)`` float64
        Ortho: mean of pairs 0, 1 as is and 2, 3 transposed (disparity axis along +x). Diagonal: mean of
        pair 4 as is and pair 5 flipped vertically (row -> 14 - row), both along the main diagonal x = y.
        NaN where a group has no pair.
    n_ortho, n_diag : ``(tiles,)`` int64
        How many pairs were averaged into each group (4 and 2 with the default mask).
    """
    corr = np.asarray(corr, dtype=np.float64)
    if corr.ndim != 4 or corr.shape[1:] != (NUM_PAIRS, CORR_SIZE, CORR_SIZE):
        raise ValueError(f"corr: expected shape (tiles, 6, 15, 15), got {corr.shape}")
    tiles = corr.shape[0]
    if pairs_mask is None:
        mask = np.ones((tiles, NUM_PAIRS), dtype=bool)
    else:
        mask = np.asarray(pairs_mask)
        if mask.dtype != bool:
            raise TypeError(f"pairs_mask: expected a bool array, got dtype {mask.dtype}")
        if mask.shape not in ((NUM_PAIRS,), (tiles, NUM_PAIRS)):
            raise ValueError(f"pairs_mask: expected shape (6,) or ({tiles}, 6), got {mask.shape}")
        mask = np.broadcast_to(mask, (tiles, NUM_PAIRS))
    present = ~np.all(np.isnan(corr), axis=(2, 3))  # (tiles, 6); an all-NaN pair is a missing pair
    use = mask & present

    def aligned(pair):
        if pair in TRANSPOSED_PAIRS:
            return np.swapaxes(corr[:, pair], -1, -2)
        if pair in FLIPPED_PAIRS:
            return corr[:, pair, ::-1, :]
        return corr[:, pair]

    def mean_of(pairs):
        total = np.zeros((tiles, CORR_SIZE, CORR_SIZE))
        for pair in pairs:
            total += np.where(use[:, pair, None, None], aligned(pair), 0.0)
        count = use[:, list(pairs)].sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            group = total / count[:, None, None]  # 0 / 0 -> NaN for an empty group
        return group, count.astype(np.int64)

    ortho, n_ortho = mean_of(ORTHO_PAIRS)
    diag, n_diag = mean_of(DIAG_PAIRS)
    return ortho, diag, n_ortho, n_diag


def _shift(a, di: int, dj: int):
    """Move the content of ``(T, N, N)`` masks by (di rows, dj columns), filling with False."""
    out = np.zeros_like(a)
    n = a.shape[-1]
    src_i = slice(max(-di, 0), n - max(di, 0))
    dst_i = slice(max(di, 0), n - max(-di, 0))
    src_j = slice(max(-dj, 0), n - max(dj, 0))
    dst_j = slice(max(dj, 0), n - max(-dj, 0))
    out[:, dst_i, dst_j] = a[:, src_i, src_j]
    return out


def _convex_mask(values, valid, hwnd: int, cnvx_weight: float):
    """Region-grown sample mask in the local box around the start cell (C.4, ``filterConvex``).

    values: ``(T, N, N)`` box of one group, N = 2 hwnd + 1, start at (hwnd, hwnd), NaN outside the tile.
    valid: ``(T, N, N)`` bool, box cell inside the 15x15 tile (the box clipped to the tile is a rectangle).
    Returns the mask weight ``(T, N, N)``: 1 for selected convex cells, ``cnvx_weight`` for selected
    non-convex cells and for the still-empty cells of the 3x3 around the start, 0 elsewhere.
    """
    n = 2 * hwnd + 1
    convex = np.zeros_like(valid)
    v = values
    inner = v[:, 1:-1, 1:-1]
    # A NaN neighbour (outside the tile = on the clipped box edge, or missing data) makes the test False,
    # so "convex" is only ever true strictly inside the clipped box, as in the spec.
    convex[:, 1:-1, 1:-1] = (2 * inner > v[:, 1:-1, :-2] + v[:, 1:-1, 2:]) & (
        2 * inner > v[:, :-2, 1:-1] + v[:, 2:, 1:-1]
    )
    convex &= valid
    di, dj = np.meshgrid(np.arange(n) - hwnd, np.arange(n) - hwnd, indexing="ij")
    sel = np.zeros_like(valid)
    sel[:, hwnd, hwnd] = valid[:, hwnd, hwnd]
    # Growth directions: (ring cells on this side, outward move, side-cell test and moves).
    sides = (
        (lambda k: (di == -k) & (np.abs(dj) <= k), (-1, 0), dj, ((0, -1), (0, 1))),  # up
        (lambda k: (di == k) & (np.abs(dj) <= k), (1, 0), dj, ((0, -1), (0, 1))),  # down
        (lambda k: (dj == -k) & (np.abs(di) <= k), (0, -1), di, ((-1, 0), (1, 0))),  # left
        (lambda k: (dj == k) & (np.abs(di) <= k), (0, 1), di, ((-1, 0), (1, 0))),  # right
    )
    for ring in range(hwnd):
        # Every ring grows from the previous selection; a ring that adds nothing leaves the next rings
        # empty too, so running all rings equals the spec's early stop.
        source = sel & (convex | (ring == 0))  # the start cell is exempt from the convexity test
        new = sel.copy()
        for ring_cells, (oi, oj), across, ((ai, aj), (bi, bj)) in sides:
            reached = _shift(source & ring_cells(ring)[None], oi, oj) & valid
            new |= reached
            conv_reached = reached & convex  # convex => all 4 neighbours lie in the clipped box
            new |= _shift(conv_reached & (across <= 0)[None], ai, aj)
            new |= _shift(conv_reached & (across >= 0)[None], bi, bj)
        sel = new
    weight = np.where(sel, np.where(convex, 1.0, cnvx_weight), 0.0)
    centre = np.zeros((n, n), dtype=bool)
    centre[hwnd - 1 : hwnd + 2, hwnd - 1 : hwnd + 2] = True
    fill = centre[None] & valid & (weight == 0.0)
    return np.where(fill, cnvx_weight, weight)


def _gather_box(group, row0, col0, hwnd: int):
    """Box ``(T, N, N)`` of ``group (T, 15, 15)`` centred at (row0, col0) ``(T,)``; NaN and invalid outside."""
    off = np.arange(-hwnd, hwnd + 1)
    rows = row0[:, None, None] + off[None, :, None]
    cols = col0[:, None, None] + off[None, None, :]
    valid = (rows >= 0) & (rows < CORR_SIZE) & (cols >= 0) & (cols < CORR_SIZE)
    t = np.arange(group.shape[0])[:, None, None]
    box = group[t, np.clip(rows, 0, CORR_SIZE - 1), np.clip(cols, 0, CORR_SIZE - 1)]
    return np.where(valid, box, np.nan), valid


def peak_variance(ortho, diag, ixc, params: LmaParams):
    """Low-pass variance ``(T,)`` [px^2] that widens each tile's too-narrow peak (C.4 "Peak widening").

    Per group the width is measured at the largest of the three cells on its axis around the start cell
    (ortho (ixc + k, 0), diagonal (ixc + k, ixc + k), k = -1..1; so within about half a pixel of the peak),
    across the axis, where the cells are symmetric about the peak: ortho (0, -+1), diagonal the anti-diagonal
    cells (-+1, +-1) at distance sqrt 2. The log curvature c = -ln(v- v+ / v0^2) / d^2 (d^2 = 1 or 2, each
    ratio floored at ``WIDTH_FLOOR``, c >= 0) is exactly 1 / sigma^2 for a Gaussian peak. The mean c over the
    usable groups (centre > 0, neighbours finite) gives sigma_p^2 = 1 / c; where sigma_p < ``peak_sigma_min``
    the variance is peak_sigma^2 - sigma_p^2, else 0 (also where nothing is usable).
    """
    tiles = ixc.shape[0]
    t = np.arange(tiles)[:, None]
    curv_sum = np.zeros(tiles)
    count = np.zeros(tiles)
    for group, diagonal in ((ortho, False), (diag, True)):
        cells = ixc[:, None] + CORR_CENTRE + np.arange(-1, 2)
        inside = (cells >= 0) & (cells < CORR_SIZE)
        clipped = np.clip(cells, 0, CORR_SIZE - 1)
        on_axis = group[t, clipped if diagonal else CORR_CENTRE, clipped]
        on_axis = np.where(inside & np.isfinite(on_axis), on_axis, -np.inf)
        col = cells[t[:, 0], np.argmax(on_axis, axis=1)]  # no finite cell: a NaN box below, not usable
        box, _ = _gather_box(group, col if diagonal else np.full_like(col, CORR_CENTRE), col, 1)
        v0 = box[:, 1, 1]
        minus, plus, dist2 = (box[:, 2, 0], box[:, 0, 2], 2.0) if diagonal else (box[:, 0, 1], box[:, 2, 1], 1.0)
        usable = np.isfinite(v0) & (v0 > 0) & np.isfinite(minus) & np.isfinite(plus)
        v0 = np.where(usable, v0, 1.0)
        floor = WIDTH_FLOOR * v0
        ratio = np.where(usable, np.maximum(minus, floor) * np.maximum(plus, floor) / v0**2, 1.0)
        curv_sum += np.where(usable, np.maximum(-np.log(ratio), 0.0) / dist2, 0.0)
        count += usable
    curv = curv_sum / np.maximum(count, 1.0)
    narrow = curv * params.peak_sigma_min**2 > 1.0  # sigma_p < peak_sigma_min (curv 0: infinitely wide)
    sigma2 = 1.0 / np.where(narrow, curv, 1.0)
    return np.where(narrow, np.clip(params.peak_sigma**2 - sigma2, 0.0, None), 0.0)


def widen(group, variance):
    """Separable Gaussian low-pass of ``group (T, 15, 15)`` with per-tile ``variance (T,)`` [px^2] (> 0).

    Taps up to ``WIDEN_RADIUS``, normalised over the finite cells (cells outside the tile and NaN cells do not
    count); NaN cells stay NaN. As matrix products: (K v K) / (K m K), K the tile's symmetric band matrix.
    """
    lag = np.arange(CORR_SIZE)
    diff = (lag[:, None] - lag[None, :]).astype(np.float64)
    var = np.asarray(variance, dtype=np.float64)[:, None, None]
    kernel = np.where(np.abs(diff) <= WIDEN_RADIUS, np.exp(-(diff**2) / (2.0 * var)), 0.0)  # (T, 15, 15)
    finite = np.isfinite(group)
    num = kernel @ np.where(finite, group, 0.0) @ kernel
    den = kernel @ finite.astype(np.float64) @ kernel
    return np.where(finite & (den > 0), num / np.where(den > 0, den, 1.0), np.nan)


def _samples(ortho, diag, ixc, n_ortho, n_diag, params: LmaParams):
    """Sample values, raw weights and coordinates ``(T, S)``, and the group of each sample ``(S,)`` (0 ortho,
    1 diagonal), S = 2 (2 hwnd + 1)^2; cells that are not samples have weight 0."""
    h = params.hwnd
    centre = ixc + CORR_CENTRE
    off = np.arange(-h, h + 1)
    di, dj = np.meshgrid(off, off, indexing="ij")
    values, weights, xs, ys, groups = [], [], [], [], []
    for group, row0, count, diagonal in (
        (ortho, np.full_like(centre, CORR_CENTRE), n_ortho, False),
        (diag, centre, n_diag, True),
    ):
        box, valid = _gather_box(group, row0, centre, h)
        mask = _convex_mask(box, valid, h, params.cnvx_weight)
        finite = np.isfinite(box)
        v = np.where(finite, box, 0.0)
        w = mask * count[:, None, None] * np.abs(v) ** params.vasw_pwr
        w = np.where(finite & (w > 0), w, 0.0)  # the spec keeps only samples with weight > 0
        if diagonal:  # rotated coordinates of pixel lag (ixc + dj, ixc + di)
            x = ixc[:, None, None] + (di + dj)[None] / 2.0
            y = np.broadcast_to((di - dj)[None] / 2.0, x.shape)
        else:
            x = ixc[:, None, None] + dj[None].astype(np.float64)
            y = np.broadcast_to(di[None].astype(np.float64), x.shape)
        tiles = v.shape[0]
        values.append(v.reshape(tiles, -1))
        weights.append(w.reshape(tiles, -1))
        xs.append(x.reshape(tiles, -1))
        ys.append(y.reshape(tiles, -1))
        groups.append(np.full(values[-1].shape[1], int(diagonal)))
    return (np.concatenate(values, 1), np.concatenate(weights, 1), np.concatenate(xs, 1),
            np.concatenate(ys, 1), np.concatenate(groups))
