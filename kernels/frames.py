"""Frame preparation and tile tasks (tile_processor.md §1.4): pair-clamped padding and per-camera tile centres.

Per-thread kernels (no tiles): they touch every pixel or every (tile, camera) once.
"""

import warp as wp

from tpnet_gpu.runtime.warp_setup import kernel_module_options

# Margin of the padded frames. Even, so padding keeps the Bayer parity; >= 17, so that *any* integer window
# corner can be moved onto the padded frame without changing what the pair-preserving clamp reads (see
# ``window_corner``): every index left of the image reads q & 1, every index right of it reads size - 2 + (q & 1).
PAD = 18
WINDOW = 16
HALF_WINDOW = 8
TILE_STEP = 8
# Centres further than this from the image (pixels) are clamped before rounding (int32 safety only).
CENTRE_LIMIT = 1.0e6

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)


@wp.func
def pair_clamp(q: int, size: int) -> int:
    """Pair-preserving clamp: q < 0 -> q & 1, q >= size -> size - 2 + (q & 1) (keeps the index parity)."""
    if q < 0:
        return q & 1
    if q >= size:
        return size - 2 + (q & 1)
    return q


@wp.func
def window_corner(itl: int, size: int) -> int:
    """Index into the padded frame of a window whose image corner is ``itl`` (any value).

    Windows wholly outside the image read the same clamped values for any corner of the same parity, so they
    are moved next to the image; the padded read then equals the pair-clamped read exactly.
    """
    corner = itl
    if itl < -WINDOW:
        corner = -WINDOW - (itl & 1)
    if itl > size:
        corner = size + ((itl - size) & 1)
    return corner + PAD


@wp.kernel
def pad_frames(frames: wp.array3d(dtype=wp.float32), padded: wp.array3d(dtype=wp.float32)):
    """padded[cam, y, x] = frames[cam, clamp(y - PAD), clamp(x - PAD)]; padded is (cams, H + 2 PAD, W + 2 PAD)."""
    cam, y, x = wp.tid()
    height = frames.shape[1]
    width = frames.shape[2]
    padded[cam, y, x] = frames[cam, pair_clamp(y - PAD, height), pair_clamp(x - PAD, width)]


@wp.kernel
def ideal_tile_centres(
    disparity: wp.array2d(dtype=wp.float32),
    offsets: wp.array(dtype=wp.vec2f),
    centres: wp.array3d(dtype=wp.float32),
):
    """Tile centres of an ideal rig (geometry_and_lma.md A.2): camera i sees tile (tx, ty) at c - d r_i.

    disparity: (tiles_y, tiles_x) target disparity, px; offsets: (cams,) r_i in baselines; centres:
    (tiles, cams, 2) (x, y) in that camera's pixels, c = (8 tx + 4, 8 ty + 4).
    """
    ty, tx, cam = wp.tid()
    d = disparity[ty, tx]
    tile = ty * disparity.shape[1] + tx
    centres[tile, cam, 0] = float(TILE_STEP * tx + TILE_STEP // 2) - d * offsets[cam][0]
    centres[tile, cam, 1] = float(TILE_STEP * ty + TILE_STEP // 2) - d * offsets[cam][1]
