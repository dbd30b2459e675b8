"""Taichi twin of kernels/fused.py: raw frames -> pair correlations (and network layers) in one kernel, without
the CLT buffer (tile_processor.md §1.4, §3-§6; network.md §1).

Two loops in one launch. First a task list: the indices of the active tiles, compacted with an atomic counter
(their order varies between runs; every tile's results are its own, so the outputs do not); inactive tiles get
their outputs cleared there (finite and valid 0, correlations and layers zero), the correlations and layers only
where ``written`` / ``layers_written`` say an earlier pass left some (kernels/fused.py). Then per worker ``slot`` (a CPU
task or a GPU thread) every slots-th task of the list: per tile every camera's window is converted (only the
colours the correlation uses, ``used``) into the slot's own few-KB scratch, which stays in cache, and every pair
is correlated from there (the same ``ti.func``s as the split kernels, kernels/taichi_convert.py and
kernels/taichi_correlate.py).

Layouts: ``scratch`` (slots * cams * U * 4, 8, 8) [slot, cam, used colour, q]; ``tasks`` (tiles,) int32;
``count`` (1,) int32; ``written``, ``layers_written`` (tiles,) uint8; the rest as the split kernels.
"""

import taichi as ti

from tpnet_gpu.kernels.taichi_convert import (
    axis_basis, camera_window, forward_colour, kernel_base, store_clt, window_flags,
)
from tpnet_gpu.kernels.taichi_correlate import correlate_pair, tile_layers, zero_correlations
from tpnet_gpu.kernels.taichi_types import F32_1D, F32_3D, I32_1D, I32_2D, U8_1D, V8_1D, V8_2D
from tpnet_gpu.layout import NET_LAYERS, NET_SIDE


@ti.func
def clear_layers(tile: ti.i32, layers: ti.template()):
    size = NET_LAYERS * NET_SIDE * NET_SIDE
    for i in range(tile * size, (tile + 1) * size):
        layers[i] = 0.0


@ti.func
def clear_tile(tile: ti.i32, npairs: ti.i32, corr: ti.template(), layers: ti.template(), with_layers: ti.i32):
    """Zero correlations (and layers) of a tile that has non-finite input."""
    zero_correlations(corr, tile * npairs, npairs)
    if with_layers != 0:
        clear_layers(tile, layers)


@ti.kernel
def fused_tiles(
    padded: F32_3D,
    centres: F32_3D,
    active: U8_1D,
    masks: F32_3D,
    kernels: V8_2D,
    kernel_rows: ti.i32,
    kernel_cols: ti.i32,
    use_kernels: ti.i32,
    image_height: ti.i32,
    image_width: ti.i32,
    colours: ti.i32,
    used: I32_1D,
    positions: I32_1D,
    weights: F32_1D,
    pairs: I32_2D,
    fat_zero: ti.f32,
    lpf_rb: V8_1D,
    lpf_corr: V8_1D,
    net_offset: ti.f32,
    with_layers: ti.i32,
    tasks: I32_1D,
    count: I32_1D,
    scratch: V8_2D,
    corr: F32_1D,
    layers: F32_1D,
    finite: U8_1D,
    valid: U8_1D,
    written: U8_1D,
    layers_written: U8_1D,
):
    """Arguments as the split kernels (convert_tiles, correlate_tiles); used/positions/weights (U,): the used
    colours, their places in the scratch (0..U-1) and weights; with_layers (0 / 1): write the quad's
    network layers (else ``layers`` is not touched; a launch argument, not a template: one kernel to compile and
    to load at each start, ~0.4 s of a warm start saved). Outputs: corr, layers, finite, valid; tasks and count are
    the task list; written / layers_written: which tiles' correlations / layers may be non-zero (read, updated)."""
    tiles = centres.shape[0]
    cams = centres.shape[1]
    npairs = pairs.shape[0]
    n_used = used.shape[0]
    block = cams * n_used * 4  # scratch entries of one slot
    slots = scratch.shape[0] // block
    count[0] = 0
    for tile in range(tiles):
        if active[tile] != 0:
            tasks[ti.atomic_add(count[0], 1)] = tile
            written[tile] = ti.u8(1)
            if with_layers != 0:
                layers_written[tile] = ti.u8(1)
        else:
            finite[tile] = ti.u8(0)
            valid[tile] = ti.u8(0)
            if written[tile] != 0:
                written[tile] = ti.u8(0)
                zero_correlations(corr, tile * npairs, npairs)
            if with_layers != 0:
                if layers_written[tile] != 0:
                    layers_written[tile] = ti.u8(0)
                    clear_layers(tile, layers)
    n = count[0]
    for slot in range(slots):
        i = slot
        while i < n:  # tasks slot, slot + slots, ...: equal shares in any order of the list
            tile = tasks[i]
            all_finite = 1
            all_inside = 1
            for cam in range(cams):
                win = camera_window(centres, tile, cam, image_height, image_width, kernel_rows, kernel_cols)
                flags = window_flags(padded, cam, win.oy, win.ox)
                all_finite *= win.finite * flags[0]
                all_inside *= win.inside * flags[1]  # featureless: not valid
                bx = axis_basis(win.sx)
                by = axis_basis(win.sy)
                for u in range(n_used):
                    colour = used[u]
                    g = forward_colour(padded, cam, win.oy, win.ox, masks, win.parity * colours + colour, bx, by)
                    store_clt(g, kernels, kernel_base(cam, win, kernel_rows, kernel_cols, colours, colour),
                              use_kernels, scratch, slot * block + (cam * n_used + u) * 4)
            finite[tile] = ti.u8(all_finite)
            valid[tile] = ti.u8(all_finite * all_inside)
            if all_finite == 0:
                clear_tile(tile, npairs, corr, layers, with_layers)
            else:
                for p in range(npairs):
                    base_a = slot * block + pairs[p, 0] * n_used * 4
                    base_b = slot * block + pairs[p, 1] * n_used * 4
                    correlate_pair(scratch, base_a, base_b, used, positions, weights, colours, fat_zero, lpf_rb,
                                   lpf_corr, corr, tile * npairs + p)
                if with_layers != 0:
                    tile_layers(corr, tile, net_offset, layers)
            i += slots
