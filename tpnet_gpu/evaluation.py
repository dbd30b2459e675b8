"""Accuracy metrics against rendered ground truth, shared by the benches (baseline, network).

Tile classes (over a tile grid ``(tiles_y, tiles_x)``):
* ``flat`` - fronto-parallel textured: confidence > 0.5, window depth spread < ``flat_spread`` px and the 3x3
  neighbourhood's ground-truth max - min < ``flat_spread`` px;
* ``edge`` - the 3x3 neighbourhood's ground-truth max - min > 1 px (the paper's hard tiles);
* ``low_texture`` - confidence < 0.3 and not an edge (sky, flat colours);
The one-tile border of the grid is left out (its windows fall off the image).
"""

from __future__ import annotations

import numpy as np

SPREAD_BINS = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, np.inf)


def neighbourhood_spread(gt: np.ndarray) -> np.ndarray:
    """max - min of the ground truth over each tile's 3x3 neighbourhood (edge-replicated), ``(ty, tx)``."""
    padded = np.pad(np.asarray(gt, dtype=np.float64), 1, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, (3, 3))
    return windows.max(axis=(-2, -1)) - windows.min(axis=(-2, -1))


def tile_classes(gt: np.ndarray, confidence: np.ndarray, spread: np.ndarray, *, flat_spread: float = 0.25) -> dict:
    """Boolean masks ``(ty, tx)`` of the classes in the module docstring, plus ``all`` (the interior)."""
    interior = np.zeros(gt.shape, dtype=bool)
    interior[1:-1, 1:-1] = True
    s3 = neighbourhood_spread(gt)
    edge = interior & (s3 > 1.0)
    return {
        "all": interior,
        "flat": interior & (confidence > 0.5) & (spread < flat_spread) & (s3 < flat_spread),
        "edge": edge,
        "low_texture": interior & (confidence < 0.3) & ~edge,
    }


GROSS_ERROR = 1.0  # px: errors beyond this are counted as outliers (wrong match, e.g. a periodic texture)


def error_stats(estimate: np.ndarray, gt: np.ndarray, mask: np.ndarray, common: np.ndarray | None = None) -> dict:
    """RMSE, median |error|, coverage (share of the masked tiles with a finite estimate), the share of gross
    errors (|error| > 1 px among the finite ones) and the RMSE of the rest (``rmse_inliers``). With ``common``
    (a mask of tiles chosen the same for every method, e.g. :func:`reference_inliers`), also ``rmse_common``:
    the RMSE over the tiles of ``mask & common`` the estimate covers (its ``coverage`` says how many it misses)."""
    extra = {}
    if common is not None:
        sel = np.asarray(mask, dtype=bool) & np.asarray(common, dtype=bool)
        err_c = np.asarray(estimate, dtype=np.float64)[sel] - np.asarray(gt, dtype=np.float64)[sel]
        err_c = err_c[np.isfinite(err_c)]
        extra["rmse_common"] = float(np.sqrt(np.mean(err_c**2))) if err_c.size else float("nan")
    est = np.asarray(estimate, dtype=np.float64)[mask]
    ref = np.asarray(gt, dtype=np.float64)[mask]
    ok = np.isfinite(est)
    err = est[ok] - ref[ok]
    inliers = err[np.abs(err) <= GROSS_ERROR]
    return {
        "tiles": int(mask.sum()),
        "coverage": float(ok.mean()) if ok.size else 0.0,
        "rmse": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
        "median_abs": float(np.median(np.abs(err))) if err.size else float("nan"),
        "gross": float(np.mean(np.abs(err) > GROSS_ERROR)) if err.size else float("nan"),
        "rmse_inliers": float(np.sqrt(np.mean(inliers**2))) if inliers.size else float("nan"),
        **extra,
    }


def reference_inliers(reference: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Tiles where the reference method's error is finite and <= 1 px: the common tile set of the paper's
    protocol (network.md §7: the heuristic within ``ofs_t`` of the ground truth), the same for every method."""
    err = np.asarray(reference, dtype=np.float64) - np.asarray(gt, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(err) & (np.abs(err) <= GROSS_ERROR)


def rmse_by_spread(estimate: np.ndarray, gt: np.ndarray, mask: np.ndarray, bins=SPREAD_BINS) -> list[dict]:
    """RMSE per bin of the 3x3 ground-truth spread (the paper's Figure 8), over the masked finite tiles."""
    s3 = neighbourhood_spread(gt)
    out = []
    for low, high in zip(bins[:-1], bins[1:]):
        sel = mask & (s3 >= low) & (s3 < high)
        stats = error_stats(estimate, gt, sel)
        out.append({"spread_low": float(low), "spread_high": float(high), **stats})
    return out
