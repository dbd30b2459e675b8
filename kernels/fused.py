"""Fused tile pass: raw frames -> pair correlations in one launch, without the CLT buffer (tile_processor.md
§1.4, §3-§6). The network layers follow as correlate.network_layers.

``compact_tasks`` (per tile) lists the active tiles with an atomic counter (``count`` must be 0 before it; on the
CPU a launch is serial, so the list is in tile order) and clears the outputs of the inactive ones: finite and
valid always, the correlations only where ``written`` says an earlier pass left some (a sparse pass over 1 % of a
5 MPix frame spent ~0.1 s zeroing 420 MB that was zero already); an active tile is marked written. ``fused_tiles``
then runs ``slots`` thread blocks of CUDA_BLOCK_DIM lanes; block ``slot`` takes tasks slot, slot + slots, ...
(one tile at a time, one block per tile in flight): every camera's window converted for the used colours into
the block's own scratch (convert.convert_camera), then every pair correlated from there
(correlate.correlate_pair). A block reads back exactly the 8x8 tiles it stored, with the same shape, so every
lane reads what it wrote itself and no barrier is needed.

Layouts: ``tasks`` (tiles,) int32; ``count`` (1,) int32; ``written`` (tiles,) bool; ``scratch`` (slots * cams * U * 4, 8, 8)
[slot, cam, used colour, q]; the rest as convert.py and correlate.py.
"""

import warp as wp

from tpnet_gpu.kernels.convert import convert_camera
from tpnet_gpu.kernels.correlate import correlate_pair, zero_correlations
from tpnet_gpu.runtime.warp_setup import kernel_module_options

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)


@wp.kernel
def reset_count(count: wp.array(dtype=wp.int32)):
    count[0] = 0


@wp.kernel
def compact_tasks(
    active: wp.array(dtype=wp.bool),
    npairs: int,
    tasks: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    finite: wp.array(dtype=wp.bool),
    valid: wp.array(dtype=wp.bool),
    corr: wp.array3d(dtype=wp.float32),
    written: wp.array(dtype=wp.bool),
):
    """Per tile: append an active tile to ``tasks`` (and mark it ``written``); an inactive one gets finite/valid
    False and zero correlations (zeroed only if ``written``, which it then clears)."""
    tile = wp.tid()
    if active[tile]:
        tasks[wp.atomic_add(count, 0, 1)] = tile
        written[tile] = True
        return
    finite[tile] = False
    valid[tile] = False
    if not written[tile]:
        return
    written[tile] = False
    for i in range(npairs):
        for r in range(corr.shape[1]):
            for c in range(corr.shape[2]):
                corr[tile * npairs + i, r, c] = 0.0


@wp.kernel
def fused_tiles(
    tasks: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    slots: int,
    padded: wp.array3d(dtype=wp.float32),
    centres: wp.array3d(dtype=wp.float32),
    masks: wp.array3d(dtype=wp.float32),
    k_rows: wp.array2d(dtype=wp.float32),
    n_rows: wp.array2d(dtype=wp.float32),
    n_cols: wp.array2d(dtype=wp.float32),
    k_cols: wp.array2d(dtype=wp.float32),
    kernels: wp.array3d(dtype=wp.float32),
    kernel_rows: int,
    kernel_cols: int,
    use_kernels: bool,
    image_height: int,
    image_width: int,
    colours: int,
    used: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.int32),
    weights: wp.array(dtype=wp.float32),
    pairs: wp.array2d(dtype=wp.int32),
    fat_zero: float,
    lpf_rb: wp.array2d(dtype=wp.float32),
    lpf_corr: wp.array2d(dtype=wp.float32),
    lags_cos: wp.array2d(dtype=wp.float32),
    lags_sin: wp.array2d(dtype=wp.float32),
    freqs_cos: wp.array2d(dtype=wp.float32),
    freqs_sin: wp.array2d(dtype=wp.float32),
    scratch: wp.array3d(dtype=wp.float32),
    corr: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    valid: wp.array(dtype=wp.bool),
):
    """Launched with dim ``slots``; used/positions/weights (U,): the used colours, their places 0..U-1 in the
    scratch and weights; the other arguments as convert_tiles and correlate_tiles."""
    slot = wp.tid()
    cams = centres.shape[1]
    npairs = pairs.shape[0]
    n_used = used.shape[0]
    block = slot * cams * n_used * 4
    i = slot
    while i < count[0]:
        tile = tasks[i]
        all_finite = bool(True)
        all_inside = bool(True)
        for cam in range(cams):
            cam_finite, cam_inside = convert_camera(
                padded, centres, tile, cam, masks, k_rows, n_rows, n_cols, k_cols, kernels, kernel_rows,
                kernel_cols, use_kernels, image_height, image_width, colours, used, scratch,
                block + cam * n_used * 4,
            )
            all_finite = all_finite and cam_finite
            all_inside = all_inside and cam_inside
        finite[tile] = all_finite
        valid[tile] = all_finite and all_inside
        if all_finite:
            for p in range(npairs):
                correlate_pair(scratch, block + pairs[p, 0] * n_used * 4, block + pairs[p, 1] * n_used * 4, used,
                               positions, weights, colours, fat_zero, lpf_rb, lpf_corr, lags_cos, lags_sin,
                               freqs_cos, freqs_sin, corr, tile * npairs + p)
        else:
            zero_correlations(corr, tile * npairs, npairs)
        i += slots
