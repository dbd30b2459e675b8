"""Operations on a tile grid of disparities (disparity.md §5): neighbourhoods, the two-depth flag, and
``settle`` (weak outliers onto their surface). Torch on the grid's device, vectorised over tiles."""

from __future__ import annotations

import torch

# A tile whose 3x3 neighbourhood of final disparities spans more than this sees two depths in its 16x16 window
# (the neighbours' centres are 8 px away, inside it). On 24 rendered tuning scenes: precision 0.64 / recall 0.52
# against the renderer's depth-edge tiles, 27 % of the flagged tiles gross vs 4 % of the rest (a second-peak
# test reached a precision of 0.14-0.23). The engine ranks them lower (engine.TWO_DEPTH_WEIGHT).
TWO_DEPTH_SPREAD = 1.0
# A weak tile (strength < WEAK_STRENGTH) more than WEAK_OFF px from the strength-weighted mean of its surface in
# its 3x3 neighbourhood (the tiles within SURFACE_BAND of the neighbourhood's median, at least SURFACE_MIN of the
# 9) takes that mean (``settle``): its own peak is mostly noise. A weak tile off that surface moves only when it
# is isolated (at most ISOLATED tiles of the 3x3, itself included, within SURFACE_BAND of it), so a structure one
# tile wide (3 in a row) keeps its disparity. 36 rendered dev scenes (seeds 500-900, none held out), p2 = 0.35:
# flat gross 0.71 -> 0.62 % (24 tuning scenes), 2.41 -> 2.25 % (12 check scenes); flat own-inlier RMSE
# 0.094 -> 0.087 / 0.113 -> 0.105 px. SURFACE_BAND 1.0 -> 1.5 (with the engine's occlusion step; 2.0 measured
# no better and a worse RMSE): a weak tile 1-1.5 px off its surface, its own peak pulled there by noise, was
# left there (43 of the dev scenes' 598 gross flat tiles were 1-1.5 px off, 10 after): flat gross 0.37 -> 0.31 %
# / 1.96 -> 1.91 %, flat own-inlier RMSE 0.0869 -> 0.0863 / 0.1066 -> 0.1067 px, all tiles either surface
# 1.66 -> 1.55 % / 2.92 -> 2.83 %.
WEAK_STRENGTH = 0.3
WEAK_OFF = 0.5
SURFACE_BAND = 1.5
SURFACE_MIN = 5
ISOLATED = 2
# A tile refinement left unmeasured, whose first-stage answer was clear and lies within FILL_BAND px of its
# measured neighbours' median, takes the strength-weighted mean of those neighbours within FILL_BAND px of that
# answer (``fill``; the answer itself, 0.5 px bins, raised the flat own-inlier RMSE 0.087 -> 0.099 px). Rendered
# dev scenes (seeds 500-1100, none held out), 24 tuning / 16 check scenes, clear = margin >= verify_margin
# (1.0): coverage flat 94.9 -> 98.2 % / 94.2 -> 97.5 %, edge 89.8 -> 93.6 / 90.0 -> 93.3 %, all 51.4 -> 54.9 /
# 64.5 -> 68.3 % (the old loop: edge 92.9 / 93.9 %, all 55.3 / 68.2 %); flat gross 0.21 -> 0.23 / 0.40 ->
# 0.42 %, all tiles either surface 1.40 -> 2.53 / 1.37 -> 1.83 %; flat own-inlier RMSE 0.0869 -> 0.0873 /
# 0.0906 -> 0.0912 px. Margins of 0.5 / 0.75 covered more but took all tiles either to 4.9 / 3.7 %.
FILL_BAND = 1.0


def neighbourhood(grid: torch.Tensor, size: int = 3) -> torch.Tensor:
    """``(ty, tx, size * size)``: each tile's ``size`` x ``size`` neighbourhood (odd ``size``) of ``grid (ty, tx)``
    in row order (NaN beyond the edge)."""
    r = size // 2
    padded = torch.nn.functional.pad(grid[None, None], (r, r, r, r), value=float("nan"))[0, 0]
    return padded.unfold(0, size, 1).unfold(1, size, 1).reshape(*grid.shape, size * size)


def grow(mask: torch.Tensor, radius: int, out: torch.Tensor, scratch: torch.Tensor) -> torch.Tensor:
    """``out (ty, tx)`` bool: the tiles within ``radius`` tiles (Chebyshev distance) of a True tile of ``mask
    (ty, tx)``, made in place in ``out`` and ``scratch`` (bool buffers like ``mask``): no new tensor per frame."""
    for source, into, axis in ((mask, scratch, 1), (scratch, out, 0)):  # rows, then columns: a square
        into.copy_(source)
        for s in range(1, min(radius, source.shape[axis] - 1) + 1):
            into.narrow(axis, s, source.shape[axis] - s).logical_or_(source.narrow(axis, 0, source.shape[axis] - s))
            into.narrow(axis, 0, source.shape[axis] - s).logical_or_(source.narrow(axis, s, source.shape[axis] - s))
    return out


def weighted_mean(windows: torch.Tensor, weights: torch.Tensor, same: torch.Tensor):
    """``(mean, total)``, each ``(ty, tx)``: the ``weights``-weighted mean of ``windows (ty, tx, n)`` over the
    entries where ``same (ty, tx, n)`` holds (NaN entries must not), and the weight summed there (0: none, the
    mean is then 0)."""
    w = torch.where(same, weights, 0.0)
    total = w.sum(dim=-1)
    return (w * torch.nan_to_num(windows)).sum(dim=-1) / total.clamp(min=1e-12), total


def surface_mean(disparity: torch.Tensor, strength: torch.Tensor, centre: torch.Tensor, band: float, size: int = 3):
    """``(mean, total)``, each ``(ty, tx)``: the ``strength``-weighted mean of the finite tiles of each tile's
    ``size`` x ``size`` neighbourhood of ``disparity (ty, tx)`` (itself included) within ``band`` px of ``centre
    (ty, tx)``, and their summed weight (``weighted_mean``; 0: none)."""
    windows = neighbourhood(disparity, size)
    weights = neighbourhood(torch.where(torch.isfinite(disparity), strength, 0.0), size)
    return weighted_mean(windows, weights, (windows - centre[..., None]).abs() <= band)  # False for NaN


def ring_median(grid: torch.Tensor, least: int = 1) -> torch.Tensor:
    """``(ty, tx)``: the median of each tile's 8 neighbours in ``grid (ty, tx)``, NaN ones left out (NaN where
    fewer than ``least`` are finite)."""
    windows = neighbourhood(grid)
    ring = torch.cat([windows[..., :4], windows[..., 5:]], dim=-1)
    median = torch.nanmedian(ring, dim=-1).values
    return torch.where(torch.isfinite(ring).sum(dim=-1) < least, torch.full_like(median, float("nan")), median)


def fill(disparity: torch.Tensor, strength: torch.Tensor, search: torch.Tensor, clear: torch.Tensor) -> torch.Tensor:
    """``disparity (ty, tx)`` with each NaN tile filled where the first stage's answer ``search (ty, tx)`` is
    ``clear (ty, tx)`` and lies within ``FILL_BAND`` px of the median of the tile's measured neighbours
    (``ring_median``): with the ``strength (ty, tx)``-weighted mean of those neighbours within ``FILL_BAND`` px of
    the answer (the answer itself where they weigh 0); other tiles unchanged."""
    agrees = (search - ring_median(disparity)).abs() <= FILL_BAND  # False for NaN
    mean, total = surface_mean(disparity, strength, search, FILL_BAND)
    value = torch.where(total > 0, mean, search)
    return torch.where(torch.isnan(disparity) & clear & agrees, value, disparity)


def two_depth(disparity: torch.Tensor) -> torch.Tensor:
    """``(ty, tx)`` bool: measured tiles whose measured 3x3 neighbourhood spans more than ``TWO_DEPTH_SPREAD``."""
    windows = neighbourhood(disparity)
    finite = torch.isfinite(windows)
    high = torch.where(finite, windows, torch.full_like(windows, -float("inf"))).amax(dim=-1)
    low = torch.where(finite, windows, torch.full_like(windows, float("inf"))).amin(dim=-1)
    return torch.isfinite(disparity) & (high - low > TWO_DEPTH_SPREAD)


def settle(disparity: torch.Tensor, strength: torch.Tensor) -> torch.Tensor:
    """``disparity (ty, tx)`` with each weak tile that lies more than ``WEAK_OFF`` px from its surface's
    strength-weighted mean moved to that mean (see ``WEAK_STRENGTH``); strong tiles, tiles without a clear
    surface around them and weak tiles on a structure of their own keep their measurement."""
    windows = neighbourhood(disparity)
    weights = neighbourhood(torch.where(torch.isfinite(disparity), strength, torch.zeros_like(strength)))
    median = torch.nanmedian(windows, dim=-1, keepdim=True).values
    same = (windows - median).abs() <= SURFACE_BAND  # False for NaN
    mean, total = weighted_mean(windows, weights, same)
    own = ((windows - disparity[..., None]).abs() <= SURFACE_BAND).sum(dim=-1)
    on_surface = (disparity - median[..., 0]).abs() <= SURFACE_BAND
    weak = (strength < WEAK_STRENGTH) & (same.sum(dim=-1) >= SURFACE_MIN) & ((disparity - mean).abs() > WEAK_OFF)
    weak &= on_surface | (own <= ISOLATED)
    return torch.where(weak & (total > 0), mean, disparity)
