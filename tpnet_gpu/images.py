"""Small PNG previews: raw mosaics as half-size RGB, disparity maps with a colour ramp (Pillow)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpnet_gpu import tables


def raw_preview(raw: np.ndarray, cfa: str, black_level: float, white_level: float) -> np.ndarray:
    """Half-size sRGB preview ``(H/2, W/2, 3)`` uint8 of a Bayer mosaic ``(H, W)`` (2x2 binning, gamma 2.2)."""
    raw = np.asarray(raw, dtype=np.float64) - black_level
    colour = tables.cfa_colour_index(cfa, 2, 2)
    planes = {0: [], 1: [], 2: []}
    for dy in range(2):
        for dx in range(2):
            planes[int(colour[dy, dx])].append(raw[dy::2, dx::2])
    rgb = np.stack([planes[0][0], np.mean(planes[2], axis=0), planes[1][0]], axis=-1)
    rgb = np.clip(rgb / max(white_level - black_level, 1e-9) / 0.8, 0, 1) ** (1 / 2.2)
    return (rgb * 255 + 0.5).astype(np.uint8)


def colour_ramp(values: np.ndarray, low: float | None = None, high: float | None = None) -> np.ndarray:
    """Map ``(H, W)`` values to an RGB ramp (dark blue -> cyan -> yellow -> red) ``(H, W, 3)`` uint8; NaN black."""
    v = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(v)
    low = np.nanmin(v[finite]) if low is None and finite.any() else (low or 0.0)
    high = np.nanmax(v[finite]) if high is None and finite.any() else (high or 1.0)
    t = np.where(finite, np.clip((v - low) / max(high - low, 1e-12), 0, 1), 0.0)
    stops = np.array([[0.05, 0.05, 0.35], [0.0, 0.7, 0.9], [0.95, 0.9, 0.1], [0.85, 0.1, 0.05]])
    pos = t * (len(stops) - 1)
    i = np.minimum(np.floor(pos).astype(int), len(stops) - 2)
    f = (pos - i)[..., None]
    rgb = stops[i] * (1 - f) + stops[i + 1] * f
    rgb[~finite] = 0.0
    return (rgb * 255 + 0.5).astype(np.uint8)


def save_png(path, image: np.ndarray) -> Path:
    """Write an ``(H, W)`` or ``(H, W, 3|4)`` uint8 image as PNG; creates the parent folder."""
    from PIL import Image  # noqa: PLC0415 - Pillow comes with scikit-image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(path)
    return path
