"""Peers for the accuracy benchmark: what a user would otherwise pick to measure sub-pixel disparity.

* OpenCV StereoSGBM (sub-pixel output, 1/16 px) on the horizontal top pair (cameras 0 -> 1);
* OpenCV ``phaseCorrelate`` and scikit-image ``phase_cross_correlation`` (upsampled 100x) per tile on 16x16
  windows of the same pair, re-centred on their own estimate for a few passes like our refinement, starting
  from the same initial targets as the baseline.
All read a grey image demosaiced by OpenCV from each raw mosaic. Benchmark-only dependencies (extra ``bench``).
"""

from __future__ import annotations

import numpy as np

WINDOW = 16


def grey(raw: np.ndarray, black: float) -> np.ndarray:
    """float32 grey image ``(H, W)`` of a GRBG mosaic (OpenCV bilinear demosaic to grey)."""
    import cv2

    data = np.clip(raw.astype(np.float32) - black, 0, None)
    scaled = np.clip(data / max(float(data.max()), 1.0) * 65535.0, 0, 65535).astype(np.uint16)
    return cv2.cvtColor(scaled, cv2.COLOR_BayerGR2GRAY).astype(np.float32)


def sgbm(left: np.ndarray, right: np.ndarray, max_disparity: float) -> np.ndarray:
    """SGBM disparity map ``(H, W)`` of the left image (NaN where invalid); positive = nearer."""
    import cv2

    to8 = lambda im: np.clip(im / max(float(im.max()), 1.0) * 255.0, 0, 255).astype(np.uint8)  # noqa: E731
    num = int(16 * np.ceil((max_disparity + 8) / 16))
    block = 5
    matcher = cv2.StereoSGBM_create(minDisparity=0, numDisparities=num, blockSize=block, P1=8 * block * block,
                                    P2=32 * block * block, disp12MaxDiff=1, uniquenessRatio=5,
                                    mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    disparity = matcher.compute(to8(left), to8(right)).astype(np.float32) / 16.0
    return np.where(disparity >= 0, disparity, np.nan)


def sample(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` at continuous (corner-based) positions; NaN outside or where NaN."""
    h, w = image.shape
    u, v = x - 0.5, y - 0.5
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    u0 = np.clip(np.floor(u).astype(int), 0, w - 2)
    v0 = np.clip(np.floor(v).astype(int), 0, h - 2)
    fu, fv = u - u0, v - v0
    val = (image[v0, u0] * (1 - fu) * (1 - fv) + image[v0, u0 + 1] * fu * (1 - fv)
           + image[v0 + 1, u0] * (1 - fu) * fv + image[v0 + 1, u0 + 1] * fu * fv)
    return np.where(inside, val, np.nan)


def _shift_cv(a: np.ndarray, b: np.ndarray) -> float:
    import cv2

    window = cv2.createHanningWindow((WINDOW, WINDOW), cv2.CV_64F)
    (dx, _), _ = cv2.phaseCorrelate(a.astype(np.float64), b.astype(np.float64), window)
    return dx


def _shift_sk(a: np.ndarray, b: np.ndarray) -> float:
    from skimage.registration import phase_cross_correlation

    shift, _, _ = phase_cross_correlation(a, b, upsample_factor=100, normalization=None)
    return shift[1]


def _calibrated(method):
    """Sign of ``method``'s x shift for content moved right in the second window (checked on a ramp)."""
    rng = np.random.default_rng(0)
    base = rng.normal(size=(WINDOW * 4, WINDOW * 4))
    kernel = np.outer(*(2 * [np.exp(-0.5 * (np.arange(-3, 4) / 1.5) ** 2)]))
    from scipy.signal import fftconvolve

    smooth = fftconvolve(base, kernel, mode="same")
    a = smooth[20:36, 20:36]
    b = smooth[20:36, 18:34]  # b's content sits 2 px right of a's
    return 1.0 if method(a, b) > 0 else -1.0


METHODS = {"opencv-phaseCorrelate": _shift_cv, "skimage-phase_cross_correlation": _shift_sk}


def tile_peer(method_name: str, left: np.ndarray, right: np.ndarray, target: np.ndarray, passes: int = 4) -> np.ndarray:
    """Per-tile disparity ``(ty, tx)`` of the horizontal pair with a phase-correlation ``method``, re-centred on
    its own estimate for ``passes`` (integer window picks; the remainder comes from the method)."""
    method = METHODS[method_name]
    sign = _calibrated(method)
    ty_n, tx_n = target.shape
    h, w = left.shape
    d = np.asarray(target, dtype=np.float64).copy()
    for _ in range(passes):
        new = np.full_like(d, np.nan)
        for ty in range(ty_n):
            for tx in range(tx_n):
                t = d[ty, tx]
                if not np.isfinite(t):
                    continue
                cx, cy = 8 * tx + 4, 8 * ty + 4
                k0x = int(np.floor(cx + t / 2 - 8 + 0.5))  # camera 0 sees the tile at c + d/2 (x and y)
                k1x = int(np.floor(cx - t / 2 - 8 + 0.5))  # camera 1 at c + (-d/2, d/2)
                ky = int(np.floor(cy + t / 2 - 8 + 0.5))
                if min(k0x, k1x, ky) < 0 or max(k0x, k1x) + WINDOW > w or ky + WINDOW > h:
                    continue
                a = left[ky : ky + WINDOW, k0x : k0x + WINDOW]
                b = right[ky : ky + WINDOW, k1x : k1x + WINDOW]
                if a.std() == 0 or b.std() == 0:
                    continue
                s = sign * method(a, b)  # content of b sits s px right of a's
                # a feature at camera-0 x0 is at x0 - d in camera 1: s = (x0 - d - k1) - (x0 - k0)
                new[ty, tx] = k0x - k1x - s
        d = new
    return d
