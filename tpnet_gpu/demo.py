"""Built-in demonstration: a generated quad-camera scene measured by the golden reference tile processor.

A textured fronto-parallel plane at a known disparity is seen by the four cameras of an ideal quad
(geometry_and_lma.md A.2: camera i sees a virtual-camera point c at c - d r_i). Each tile is correlated for the
6 pairs at a target disparity, the residual is read from the peaks, and the target is refined; the report
gives the error against the known disparity. (Later stages replace this with the Warp pipeline.)
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import reference as ref
from tpnet_gpu import tables

QUAD_OFFSETS = np.array(tables.QUAD_OFFSETS)


def _textured_views(rng: np.random.Generator, size: int, disparity: float) -> np.ndarray:
    """Bayer colour planes ``(4, 3, size, size)`` of a periodic smooth colour texture seen at ``disparity``."""
    freq = np.fft.fftfreq(size)
    fy, fx = freq[:, None], freq[None, :]
    spectrum = np.fft.fft2(rng.normal(size=(3, size, size)) * 0.3 + rng.normal(size=(1, size, size)))
    spectrum *= np.exp(-2.0 * (np.pi * 1.5) ** 2 * (fx**2 + fy**2))
    views = []
    for offset in QUAD_OFFSETS:
        move = -disparity * offset  # content moves by -d r_i
        colour = np.fft.ifft2(spectrum * np.exp(-2j * np.pi * (fx * move[0] + fy * move[1]))).real
        cfa = tables.cfa_colour_index(tables.DEFAULT_CFA, size, size)
        views.append(ref.bayer_planes(np.take_along_axis(colour, cfa[None], axis=0)[0]))
    return np.stack(views)


def _peak(corr: np.ndarray) -> np.ndarray:
    """(m_x, m_y) of the 5x5 positive-part centroid around the integer maximum (a Bayer-safe estimator)."""
    r = corr.shape[-1] // 2
    iy, ix = np.unravel_index(np.argmax(corr), corr.shape)
    iy, ix = np.clip(iy, 2, 2 * r - 2), np.clip(ix, 2, 2 * r - 2)
    win = np.maximum(corr[iy - 2 : iy + 3, ix - 2 : ix + 3], 0.0)
    lags = np.arange(-2, 3)
    return np.array([ix - r + win.sum(0) @ lags / win.sum(), iy - r + win.sum(1) @ lags / win.sum()])


def run_reference_demo(seed: int = 0, disparity: float = 2.37, passes: int = 6) -> str:
    """Measure a plane at ``disparity`` px on a 3x3 grid of tiles; return a short text report."""
    rng = np.random.default_rng(seed)
    size = 96
    views = _textured_views(rng, size, disparity)
    centres = np.array([[cx, cy] for cy in (36.0, 48.0, 60.0) for cx in (36.0, 48.0, 60.0)])
    pair_axes = np.array([QUAD_OFFSETS[b] - QUAD_OFFSETS[a] for a, b in tables.QUAD_PAIRS])
    target = np.zeros(len(centres))
    lines = [f"tpnet demo (golden reference): plane at disparity {disparity} px, {len(centres)} tiles, 6 pairs"]
    for n in range(passes):
        clt = [ref.convert_tiles(views[i], centres - target[:, None] * QUAD_OFFSETS[i])[0] for i in range(4)]
        residual = np.zeros(len(centres))
        for (a, b), axis in zip(tables.QUAD_PAIRS, pair_axes):
            corr = ref.correlate(clt[a], clt[b], fat_zero=0.0)
            peaks = np.array([_peak(c) for c in corr])
            residual += -(peaks @ axis) / (axis @ axis)  # the peak of a pair sits at -residual * axis
        target = target + residual / len(pair_axes)
        error = np.abs(target - disparity)
        lines.append(f"pass {n + 1}: median |error| {np.median(error):.4f} px, max {error.max():.4f} px")
    return "\n".join(lines)
