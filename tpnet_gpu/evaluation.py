"""Accuracy metrics against rendered ground truth, shared by the benches (baseline, network).

Tile classes (over a tile grid ``(tiles_y, tiles_x)``):
* ``flat`` - fronto-parallel textured: confidence > 0.5, window depth spread < ``flat_spread`` px and the 3x3
  neighbourhood's ground-truth max - min < ``flat_spread`` px;
* ``edge`` - the 3x3 neighbourhood's ground-truth max - min > 1 px (the paper's hard tiles);
* ``low_texture`` - confidence < 0.3 and not an edge (sky, flat colours);
The one-tile border of the grid is left out (its windows fall off the image).

Errors (every rate is over the method's finite estimates; a NaN is a tile not covered, never an error):
* **strict** (``gross``): ``|estimate - gt| > GROSS_ERROR`` (1 px), ``gt`` the disparity of the tile's centre ray;
* **either-surface** (``gross_either``): the estimate is > 1 px from every surface of the tile's 16x16 window.
  With the renderer's ``tile_surfaces`` (per tile and surface: share of the window, min, max disparity of its
  pixels there), an estimate is either-surface correct when it is strictly correct, or when it lies in
  ``[min - 1 px, max + 1 px]`` of a surface covering at least ``MIN_SURFACE_SHARE`` (10 %) of the window
  (:func:`either_surface_correct`). A slanted plane is one surface whose range is its disparity over the window;
  a depth edge's tile is right on either side. Strictly correct implies either-surface correct, so
  ``gross_either <= gross``;
* ``rmse_inliers``: RMSE over the method's own strict inliers (``|error| <= 1 px``); ``rmse_common``: RMSE over
  the tiles a reference method gets strictly within 1 px (:func:`reference_inliers`, the same tiles for every
  method); ``new_gross``: of those tiles, the ones the method makes strictly gross (:func:`new_gross`).
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
MIN_SURFACE_SHARE = 0.1  # a window surface counts for the either-surface error when it covers this share


def _share(flags: np.ndarray) -> float:
    return float(np.mean(flags)) if flags.size else float("nan")


def is_gross(estimate: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Strict gross errors: the estimate is finite and ``|estimate - gt| > GROSS_ERROR`` (same shape)."""
    err = np.asarray(estimate, dtype=np.float64) - np.asarray(gt, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(err) & (np.abs(err) > GROSS_ERROR)


def either_surface_correct(estimate: np.ndarray, gt: np.ndarray, surfaces: np.ndarray, *,
                           min_share: float = MIN_SURFACE_SHARE) -> np.ndarray:
    """Either-surface correct (module docstring): the estimate is finite and within ``GROSS_ERROR`` of ``gt``
    or inside ``[min - GROSS_ERROR, max + GROSS_ERROR]`` of a surface with share >= ``min_share``. ``estimate``
    and ``gt`` of one shape S, ``surfaces`` of S + ``(K, 3)`` (share, min, max; NaN rows: no surface, as
    ``Rendered.tile_surfaces``). Returns a boolean array of shape S."""
    est = np.asarray(estimate, dtype=np.float64)
    surfaces = np.asarray(surfaces, dtype=np.float64)
    if surfaces.shape[:-2] != est.shape or surfaces.shape[-1] != 3:
        raise ValueError(f"surfaces: expected shape {est.shape} + (K, 3), got {surfaces.shape}")
    share, low, high = np.moveaxis(surfaces, -1, 0)
    e = est[..., None]
    with np.errstate(invalid="ignore"):
        on_surface = (share >= min_share) & (e >= low - GROSS_ERROR) & (e <= high + GROSS_ERROR)
        strict = np.abs(est - np.asarray(gt, dtype=np.float64)) <= GROSS_ERROR
    return np.isfinite(est) & (strict | on_surface.any(axis=-1))


def new_gross(estimate: np.ndarray, reference: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> dict:
    """The tiles (of ``mask``, default all) that ``reference`` gets strictly within 1 px and ``estimate`` makes
    strictly gross: ``count``, ``share`` of the reference's right tiles (NaN if none) and ``reference_right``
    (their number). A tile the estimate leaves NaN is not counted (its coverage says so)."""
    right = reference_inliers(reference, gt)
    if mask is not None:
        right &= np.asarray(mask, dtype=bool)
    return _new_gross(is_gross(estimate, gt), right)


def _new_gross(gross: np.ndarray, right: np.ndarray) -> dict:
    count, tiles = int((gross & right).sum()), int(right.sum())
    return {"count": count, "share": count / tiles if tiles else float("nan"), "reference_right": tiles}


def error_stats(estimate: np.ndarray, gt: np.ndarray, mask: np.ndarray, common: np.ndarray | None = None,
                surfaces: np.ndarray | None = None) -> dict:
    """RMSE, median |error|, coverage (share of the masked tiles with a finite estimate), ``right`` (share of
    the masked tiles with an estimate within 1 px: coverage that counts only right answers, so a method cannot
    gain it by emitting wrong ones), the share of strict gross errors (``gross``: |error| > 1 px among the
    finite ones) and the RMSE of the rest (``rmse_inliers``, the method's own inliers). With ``common`` (a mask of tiles chosen the same for every method, e.g.
    :func:`reference_inliers`), also ``rmse_common``: the RMSE over the tiles of ``mask & common`` the estimate
    covers (its ``coverage`` says how many it misses), and ``new_gross`` / ``new_gross_share``: how many of the
    tiles of ``mask & common`` the estimate makes gross, and their share (:func:`new_gross`). With
    ``surfaces`` (``gt.shape + (K, 3)``, as ``Rendered.tile_surfaces``), also ``gross_either``: the share of
    the finite estimates that are not :func:`either_surface_correct`."""
    mask = np.asarray(mask, dtype=bool)
    extra = {}
    if common is not None:
        sel = mask & np.asarray(common, dtype=bool)
        err_c = np.asarray(estimate, dtype=np.float64)[sel] - np.asarray(gt, dtype=np.float64)[sel]
        err_c = err_c[np.isfinite(err_c)]
        extra["rmse_common"] = float(np.sqrt(np.mean(err_c**2))) if err_c.size else float("nan")
        made = _new_gross(is_gross(estimate, gt), sel)
        extra["new_gross"], extra["new_gross_share"] = made["count"], made["share"]
    if surfaces is not None:
        finite = mask & np.isfinite(np.asarray(estimate, dtype=np.float64))
        extra["gross_either"] = _share(~either_surface_correct(estimate, gt, surfaces)[finite])
    est = np.asarray(estimate, dtype=np.float64)[mask]
    ref = np.asarray(gt, dtype=np.float64)[mask]
    ok = np.isfinite(est)
    err = est[ok] - ref[ok]
    inliers = err[np.abs(err) <= GROSS_ERROR]
    return {
        "tiles": int(mask.sum()),
        "coverage": float(ok.mean()) if ok.size else 0.0,
        "right": float(inliers.size / ok.size) if ok.size else 0.0,
        "rmse": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
        "median_abs": float(np.median(np.abs(err))) if err.size else float("nan"),
        "gross": _share(np.abs(err) > GROSS_ERROR),
        "rmse_inliers": float(np.sqrt(np.mean(inliers**2))) if inliers.size else float("nan"),
        **extra,
    }


def reference_inliers(reference: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Tiles where the reference method's error is finite and <= 1 px: the common tile set of the paper's
    protocol (network.md §7: the heuristic within ``ofs_t`` of the ground truth), the same for every method."""
    err = np.asarray(reference, dtype=np.float64) - np.asarray(gt, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(err) & (np.abs(err) <= GROSS_ERROR)


def confidence_ranking(estimate: np.ndarray, confidence: np.ndarray | None, gt: np.ndarray, mask: np.ndarray,
                       fractions=(0.9, 0.75), *, surfaces: np.ndarray | None = None) -> list[dict] | None:
    """Gross rates among a method's most confident tiles: of its finite estimates in ``mask`` (n tiles), sorted
    by ``confidence`` high to low (NaN confidence last; ties in array order), the first f n (rounded half up)
    for each fraction f. Per fraction: ``fraction``, ``tiles``, ``gross`` (strict) and, with ``surfaces``,
    ``gross_either`` (NaN where no tile is kept). A method without a confidence (``None``) gets None."""
    if confidence is None:
        return None
    est = np.asarray(estimate, dtype=np.float64)
    keep = np.asarray(mask, dtype=bool) & np.isfinite(est)
    conf = np.nan_to_num(np.asarray(confidence, dtype=np.float64)[keep], nan=-np.inf)
    order = np.argsort(-conf, kind="stable")
    gross = is_gross(est, gt)[keep][order]
    wrong = None if surfaces is None else ~either_surface_correct(est, gt, surfaces)[keep][order]
    out = []
    for fraction in fractions:
        tiles = int(np.floor(fraction * len(order) + 0.5))
        row = {"fraction": float(fraction), "tiles": tiles, "gross": _share(gross[:tiles])}
        if wrong is not None:
            row["gross_either"] = _share(wrong[:tiles])
        out.append(row)
    return out


def rmse_by_spread(estimate: np.ndarray, gt: np.ndarray, mask: np.ndarray, bins=SPREAD_BINS) -> list[dict]:
    """RMSE per bin of the 3x3 ground-truth spread (the paper's Figure 8), over the masked finite tiles."""
    s3 = neighbourhood_spread(gt)
    out = []
    for low, high in zip(bins[:-1], bins[1:]):
        sel = mask & (s3 >= low) & (s3 < high)
        stats = error_stats(estimate, gt, sel)
        out.append({"spread_low": float(low), "spread_high": float(high), **stats})
    return out
