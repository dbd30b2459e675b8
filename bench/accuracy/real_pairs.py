"""Real rectified stereo pairs with ground truth, and their scores per tile and per pixel (``tpnet bench real``).

Folder layouts read (``load_pair``):
* the project's ``realdata`` layout: ``left.png right.png meta.json`` (``{"gt": FILE, "gt_scale": s, "invalid": v,
  "max_disparity": n}``: disparity = value / s, ``v`` = unknown) and optionally ``mask_nonocc.png`` (palette
  index or grey value 1 / 255 = a scored non-occluded pixel);
* Middlebury 2014 / ETH3D: ``im0.png im1.png disp0GT.pfm`` (inf = unknown), optionally ``mask0nocc.png`` (255 =
  non-occluded) and ``calib.txt`` (its ``ndisp`` gives the range; else the GT's maximum + 8).
Disparity convention: ``left[y, x] ~ right[y, x - d]``.

Per tile (the pipeline's grid in the left image: tile (tx, ty) centred at (8 tx + 4, 8 ty + 4), its 16x16 window
starting at (8 tx - 4, 8 ty - 4)): GT = the half-sine-weighted mean of the window's known GT pixels (at least
half of the weight known), "fronto" = the GT's max - min over the window <= ``FRONTO_SPREAD`` px. Per pixel
(Middlebury's measures): bad 1.0 / bad 2.0 = share of scored pixels with an answer more than 1 / 2 px off,
avgerr = mean |error|; "scored" = known GT and, where a mask exists, non-occluded; no answer counts as bad, as
Middlebury counts it (and the coverage is reported beside).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpnet_gpu.layout import TILE_SIZE, TILE_STRIDE

FRONTO_SPREAD = 1.0  # px: a window whose GT spans at most this is fronto-parallel (the definition)
GROSS = 1.0  # px: a tile answer further than this from the tile's GT is wrong
MIN_KNOWN_WEIGHT = 0.5  # share of the window's weight with known GT for a tile to be scored
MIN_SURFACE_SHARE = 0.1  # either-surface: the answer fits at least this share of the window's GT


@dataclass(frozen=True, eq=False)
class Pair:
    """One rectified pair: ``left``, ``right`` (paths), ``gt (h, w)`` float64 px (NaN = unknown), ``mask (h, w)``
    bool of scored non-occluded pixels or None, ``max_disparity`` (the range searched, px)."""

    name: str
    left: Path
    right: Path
    gt: np.ndarray
    mask: np.ndarray | None
    max_disparity: float


def _read_pfm(path: Path) -> np.ndarray:
    """A one-channel PFM as ``(h, w)`` float64, top row first (PFM stores the bottom row first)."""
    with open(path, "rb") as f:
        kind = f.readline().strip()
        if kind != b"Pf":
            raise ValueError(f"{path}: expected a one-channel PFM ('Pf'), got {kind[:8]!r}")
        w, h = (int(v) for v in f.readline().split())
        scale = float(f.readline())
        data = np.fromfile(f, dtype="<f4" if scale < 0 else ">f4", count=w * h)
    if data.size != w * h:
        raise ValueError(f"{path}: expected {w * h} floats, got {data.size}")
    return np.flipud(data.reshape(h, w)).astype(np.float64)


def _read_mask(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        values = np.asarray(im)
    if values.ndim == 3:
        values = values[..., 0]
    return (values == 1) | (values == 255)


def load_pair(folder) -> Pair:
    """A pair folder of either layout (module docstring)."""
    from PIL import Image

    folder = Path(folder)
    if (folder / "meta.json").is_file():
        meta = json.loads((folder / "meta.json").read_text())
        with Image.open(folder / meta["gt"]) as im:
            raw = np.asarray(im).astype(np.float64)
        gt = np.where(raw == meta.get("invalid", 0), np.nan, raw / float(meta["gt_scale"]))
        mask_path = folder / "mask_nonocc.png"
        left, right, max_d = folder / "left.png", folder / "right.png", float(meta["max_disparity"])
    elif (folder / "disp0GT.pfm").is_file():
        gt = _read_pfm(folder / "disp0GT.pfm")
        gt[~np.isfinite(gt) | (gt <= 0)] = np.nan
        mask_path = folder / "mask0nocc.png"
        left, right = folder / "im0.png", folder / "im1.png"
        max_d = float(np.nanmax(gt)) + 8.0
        calib = folder / "calib.txt"
        if calib.is_file():
            for line in calib.read_text().splitlines():
                if line.startswith("ndisp="):
                    max_d = float(line.split("=", 1)[1])
    else:
        raise FileNotFoundError(f"{folder}: expected meta.json (realdata layout) or disp0GT.pfm (Middlebury 2014 / "
                                "ETH3D layout)")
    mask = _read_mask(mask_path) if mask_path.is_file() else None
    if mask is not None and mask.shape != gt.shape:
        raise ValueError(f"{mask_path}: expected the GT's size {gt.shape}, got {mask.shape}")
    return Pair(folder.name, left, right, gt, mask, max_d)


def half_sine() -> np.ndarray:
    """``(16, 16)`` the tile window's weights: sin(pi (i + 0.5) / 16) in each direction."""
    w = np.sin(np.pi * (np.arange(TILE_SIZE) + 0.5) / TILE_SIZE)
    return np.outer(w, w)


def tile_windows(image: np.ndarray, tiles: tuple[int, int]) -> np.ndarray:
    """``(ty, tx, 16, 16)`` each tile's window of ``image (h, w)`` (NaN outside the image)."""
    ty, tx = tiles
    pad = TILE_SIZE // 2 - TILE_STRIDE // 2
    h, w = image.shape
    padded = np.full((ty * TILE_STRIDE + 2 * pad, tx * TILE_STRIDE + 2 * pad), np.nan)
    hh, ww = min(h, ty * TILE_STRIDE + pad), min(w, tx * TILE_STRIDE + pad)
    padded[pad: pad + hh, pad: pad + ww] = image[:hh, :ww]
    view = np.lib.stride_tricks.sliding_window_view(padded, (TILE_SIZE, TILE_SIZE))
    return view[::TILE_STRIDE, ::TILE_STRIDE][:ty, :tx]


def tile_truth(gt: np.ndarray, tiles: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``(truth, spread)``, each ``(ty, tx)``: the half-sine-weighted mean of each window's known GT (NaN where
    less than ``MIN_KNOWN_WEIGHT`` of the weight is known) and the GT's max - min over the window."""
    windows = tile_windows(gt, tiles)
    weight = half_sine()
    known = np.isfinite(windows)
    w = np.where(known, weight, 0.0)
    total = w.sum(axis=(-2, -1))
    with np.errstate(invalid="ignore", divide="ignore"):
        truth = (np.where(known, windows, 0.0) * w).sum(axis=(-2, -1)) / total
        spread = np.where(known.any(axis=(-2, -1)), np.nanmax(np.where(known, windows, -np.inf), axis=(-2, -1))
                          - np.nanmin(np.where(known, windows, np.inf), axis=(-2, -1)), np.nan)
    truth = np.where(total >= MIN_KNOWN_WEIGHT * weight.sum(), truth, np.nan)
    return truth, spread


def either_correct(estimate: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """``(ty, tx)`` bool: the tile answer is within ``GROSS`` px of at least ``MIN_SURFACE_SHARE`` of its window's
    known GT (half-sine weighted): right on either side of a depth edge. False where the answer is NaN."""
    windows = tile_windows(gt, estimate.shape)
    weight = np.where(np.isfinite(windows), half_sine(), 0.0)
    with np.errstate(invalid="ignore"):
        near = np.abs(windows - estimate[..., None, None]) <= GROSS
    share = (near * weight).sum(axis=(-2, -1)) / np.maximum(weight.sum(axis=(-2, -1)), 1e-12)
    return np.isfinite(estimate) & (share >= MIN_SURFACE_SHARE)


def sample_tiles(image: np.ndarray, tiles: tuple[int, int]) -> np.ndarray:
    """A per-pixel map ``(h, w)`` scored on the tile grid: the half-sine-weighted mean of its finite values in
    each window (NaN where less than ``MIN_KNOWN_WEIGHT`` of the weight has one), ``(ty, tx)``."""
    return tile_truth(image, tiles)[0]


def tile_scores(estimate: np.ndarray, truth: np.ndarray, spread: np.ndarray, confidence: np.ndarray | None = None,
                coverage: float | None = None, either: np.ndarray | None = None,
                scene: np.ndarray | None = None) -> dict:
    """Per-tile scores of ``estimate`` (NaN = no answer; any shape) against ``truth``/``spread`` (``tile_truth``):
    coverage, share > 1 px off over the answers (strict; with ``either``, the ``either_correct`` flags, also
    the either-surface share), fronto-tile median |error|, its bias and scatter (``fronto_scatter``), and - with
    ``confidence`` and a ``coverage`` to match - the share > 1 px off among the ``coverage`` most confident
    scored tiles. ``scene``: each tile's scene (pooled scores: each scene's bias is its own; default one)."""
    scored = np.isfinite(truth)
    answered = scored & np.isfinite(estimate)
    with np.errstate(invalid="ignore"):
        err = np.abs(estimate - truth)
    fronto = answered & (spread <= FRONTO_SPREAD)
    out = {"tiles": int(scored.sum()), "coverage": float(answered.sum() / max(scored.sum(), 1)),
           "gross": float(np.mean(err[answered] > GROSS)) if answered.any() else float("nan"),
           "gross_either": (float(np.mean(~either[answered])) if answered.any() else float("nan"))
           if either is not None else None,
           "fronto_tiles": int(fronto.sum()),
           "fronto_median": float(np.median(err[fronto])) if fronto.any() else float("nan"),
           "fronto_gross": float(np.mean(err[fronto] > GROSS)) if fronto.any() else float("nan"),
           **fronto_scatter(estimate - truth, fronto & (err <= GROSS), scene)}
    if confidence is not None and coverage is not None:
        out["gross_at_coverage"] = gross_at_coverage(estimate, truth, confidence, coverage)
    return out


def fronto_scatter(error: np.ndarray, inliers: np.ndarray, scene: np.ndarray | None = None) -> dict:
    """``fronto_bias``: the median signed error of the fronto tiles within 1 px (``inliers``, bool like
    ``error``); ``fronto_scatter``: their median |error - their scene's median| (``scene``: a label per tile,
    default one scene). A scene's GT can sit a fixed fraction of a pixel off its images (a rectification or
    calibration offset): every method then shares that bias, and the fronto median measures it more than the
    method - the scatter about it is the method's precision (docs/results.md §4)."""
    scene = np.zeros(error.shape, dtype=np.int64) if scene is None else np.asarray(scene)
    if not inliers.any():
        return {"fronto_bias": float("nan"), "fronto_scatter": float("nan")}
    e, s = error[inliers], scene[inliers]
    centred = np.empty_like(e)
    for label in np.unique(s):
        centred[s == label] = e[s == label] - np.median(e[s == label])
    return {"fronto_bias": float(np.median(e)), "fronto_scatter": float(np.median(np.abs(centred)))}


def gross_at_coverage(estimate: np.ndarray, truth: np.ndarray, confidence: np.ndarray, coverage: float) -> float:
    """Share > 1 px off among the most confident answers, as many as ``coverage`` of the scored tiles (fewer if
    the method answers fewer)."""
    scored = np.isfinite(truth)
    answered = scored & np.isfinite(estimate)
    take = min(int(round(coverage * scored.sum())), int(answered.sum()))
    if take == 0:
        return float("nan")
    order = np.argsort(-np.where(answered, confidence, -np.inf), axis=None, kind="stable")[:take]
    with np.errstate(invalid="ignore"):
        err = np.abs(estimate - truth).reshape(-1)[order]
    return float(np.mean(err > GROSS))


def pixel_scores(estimate: np.ndarray, gt: np.ndarray, mask: np.ndarray | None) -> dict:
    """Middlebury's per-pixel measures of ``estimate (h, w)`` (NaN = no answer, counted bad) on the scored
    pixels (known GT, and ``mask`` where given): bad 1.0, bad 2.0, avgerr (over answered pixels), coverage."""
    scored = np.isfinite(gt) if mask is None else np.isfinite(gt) & mask
    e = estimate[scored]
    err = np.abs(e - gt[scored])
    answered = np.isfinite(e)
    with np.errstate(invalid="ignore"):
        return {"pixels": int(scored.sum()), "masked": mask is not None,
                "coverage": float(answered.mean()) if e.size else float("nan"),
                "bad1": float(np.mean(~(err <= 1.0))) if e.size else float("nan"),
                "bad2": float(np.mean(~(err <= 2.0))) if e.size else float("nan"),
                "avgerr": float(np.mean(err[answered])) if answered.any() else float("nan")}
