"""Taichi twin of kernels/frames.py: pair-clamped padding and per-camera tile centres (tile_processor.md §1.4).

Same arguments and layouts as the Warp kernels; the constants (PAD, the window sizes, the centre limit) are the
Warp module's own. Every array is an external torch tensor (``ti.types.ndarray``, zero-copy).
"""

import taichi as ti

from tpnet_gpu.kernels.frames import PAD, TILE_STEP, WINDOW
from tpnet_gpu.kernels.taichi_types import F32_2D, F32_3D


@ti.func
def pair_clamp(q: ti.i32, size: ti.i32) -> ti.i32:
    """Pair-preserving clamp: q < 0 -> q & 1, q >= size -> size - 2 + (q & 1) (keeps the index parity)."""
    out = q
    if q < 0:
        out = q & 1
    elif q >= size:
        out = size - 2 + (q & 1)
    return out


@ti.func
def window_corner(itl: ti.i32, size: ti.i32) -> ti.i32:
    """Index into the padded frame of a window whose image corner is ``itl`` (see frames.window_corner)."""
    corner = itl
    if itl < -WINDOW:
        corner = -WINDOW - (itl & 1)
    if itl > size:
        corner = size + ((itl - size) & 1)
    return corner + PAD


@ti.kernel
def pad_frames(frames: F32_3D, padded: F32_3D):
    """padded[cam, y, x] = frames[cam, clamp(y - PAD), clamp(x - PAD)]; padded is (cams, H + 2 PAD, W + 2 PAD)."""
    height = frames.shape[1]
    width = frames.shape[2]
    for cam, y in ti.ndrange(padded.shape[0], padded.shape[1]):  # a thread per row: no index division per pixel
        source = pair_clamp(y - PAD, height)
        for x in range(PAD):
            padded[cam, y, x] = frames[cam, source, pair_clamp(x - PAD, width)]
        for x in range(width):  # the row itself, a plain copy
            padded[cam, y, PAD + x] = frames[cam, source, x]
        for x in range(PAD + width, padded.shape[2]):
            padded[cam, y, x] = frames[cam, source, pair_clamp(x - PAD, width)]


@ti.kernel
def ideal_tile_centres(disparity: F32_2D, offsets: F32_2D, centres: F32_3D):
    """Tile centres of an ideal rig (geometry_and_lma.md A.2): camera i sees tile (tx, ty) at c - d r_i.

    disparity: (tiles_y, tiles_x) px; offsets: (cams, 2) r_i in baselines; centres out: (tiles, cams, 2) (x, y)
    in that camera's pixels, c = (8 tx + 4, 8 ty + 4)."""
    tiles_x = disparity.shape[1]
    for ty, tx in ti.ndrange(disparity.shape[0], tiles_x):  # a thread per tile, its cameras in turn
        d = disparity[ty, tx]
        tile = ty * tiles_x + tx
        for cam in range(offsets.shape[0]):
            centres[tile, cam, 0] = ti.cast(TILE_STEP * tx + TILE_STEP // 2, ti.f32) - d * offsets[cam, 0]
            centres[tile, cam, 1] = ti.cast(TILE_STEP * ty + TILE_STEP // 2, ti.f32) - d * offsets[cam, 1]
