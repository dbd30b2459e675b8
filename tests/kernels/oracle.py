"""The golden reference applied to a whole processor task: the oracle of the kernel tests."""

from __future__ import annotations

import numpy as np

from tpnet_gpu import reference as ref


def reference_clt(frames, centres, cfa, kernels=None):
    """CLT ``(tiles, cams, colours, 4, 8, 8)`` of raw frames ``(cams, H, W)`` at centres ``(tiles, cams, 2)``.

    kernels: optional ``(cams, rows, cols, colours, 4, 8, 8)``, selected per tile and camera at the nearest
    grid node (node n at pixel 16 n - 8), clamped.
    """
    frames = np.asarray(frames, dtype=np.float64)
    centres = np.asarray(centres, dtype=np.float64)
    out = []
    for cam in range(frames.shape[0]):
        planes = frames[cam][None] if cfa is None else ref.bayer_planes(frames[cam], cfa)
        k = None
        if kernels is not None:
            rows, cols = kernels.shape[1:3]
            c = np.nan_to_num(centres[:, cam])
            kx = np.clip(np.floor(c[:, 0] / 16).astype(int) + 1, 0, cols - 1)
            ky = np.clip(np.floor(c[:, 1] / 16).astype(int) + 1, 0, rows - 1)
            k = kernels[cam][ky, kx]
        out.append(ref.convert_tiles(planes, np.nan_to_num(centres[:, cam]), kernels=k)[0])
    return np.stack(out, axis=1)


def reference_corr(clt, pairs, **kwargs):
    """Pair correlations ``(tiles, pairs, 15, 15)`` of reference CLT tiles."""
    return np.stack([ref.correlate(clt[:, a], clt[:, b], **kwargs) for a, b in pairs], axis=1)


def relative_error(got, want) -> float:
    """max |got - want| / max |want| (the tolerance measure of the kernel tests)."""
    got = got.detach().cpu().numpy() if hasattr(got, "detach") else np.asarray(got)
    return float(np.abs(got - want).max() / np.abs(want).max())
