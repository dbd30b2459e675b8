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

Layouts: the task list, the scratch and the ``written`` flags as ``FusedWork``; the rest as the split kernels, whose
argument packs (``ConvertInputs``, ``CorrelateInputs``) ``fused_tiles`` takes as they do.
"""

import taichi as ti

from tpnet_gpu.kernels.taichi_convert import (
    ConvertInputs, axis_basis, camera_window, forward_colour, kernel_base, store_clt, window_flags,
)
from tpnet_gpu.kernels.taichi_correlate import CorrelateInputs, correlate_pair, tile_layers, zero_correlations
from tpnet_gpu.kernels.taichi_types import F32_1D, F32_3D, I32_1D, U8_1D, V8_2D
from tpnet_gpu.layout import NET_LAYERS, NET_SIDE

# The fused pass's own buffers, one pack per processor (kernels/fused.FusedWork's twin): tasks (tiles,) int32 the
# active tiles, count (1,) int32 how many; positions (U,) int32 the places 0..U-1 of the used colours in the
# scratch; scratch (slots * cams * U * 4, 8) rows of 8 (V8) [slot, cam, used colour, q, ky]; written,
# layers_written (tiles,) uint8: which tiles' correlations / layers an earlier pass may have left non-zero.
FusedWork = ti.types.argpack(tasks=I32_1D, count=I32_1D, positions=I32_1D, scratch=V8_2D, written=U8_1D,
                             layers_written=U8_1D)


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
def fused_tiles(convert: ConvertInputs, correlate: CorrelateInputs, work: FusedWork, centres: F32_3D, active: U8_1D,
                with_layers: ti.i32, corr: F32_1D, layers: F32_1D, finite: U8_1D, valid: U8_1D):
    """Arguments as the split kernels (convert_tiles, correlate_tiles) and ``FusedWork``; with_layers (0 / 1):
    write the quad's network layers (else ``layers`` is not touched; a launch argument, not a template: one kernel
    to compile and to load at each start, ~0.4 s of a warm start saved). Outputs: corr, layers, finite, valid; the
    task list and ``written`` / ``layers_written`` are read and updated."""
    tiles = centres.shape[0]
    cams = centres.shape[1]
    npairs = correlate.pairs.shape[0]
    n_used = correlate.used.shape[0]
    n_colours = convert.colours  # (a pack's member names are reserved in a kernel: taichi_types.py)
    block = cams * n_used * 4  # scratch entries of one slot
    slots = work.scratch.shape[0] // block
    work.count[0] = 0
    for tile in range(tiles):
        if active[tile] != 0:
            work.tasks[ti.atomic_add(work.count[0], 1)] = tile
            work.written[tile] = ti.u8(1)
            if with_layers != 0:
                work.layers_written[tile] = ti.u8(1)
        else:
            finite[tile] = ti.u8(0)
            valid[tile] = ti.u8(0)
            if work.written[tile] != 0:
                work.written[tile] = ti.u8(0)
                zero_correlations(corr, tile * npairs, npairs)
            if with_layers != 0:
                if work.layers_written[tile] != 0:
                    work.layers_written[tile] = ti.u8(0)
                    clear_layers(tile, layers)
    n = work.count[0]
    for slot in range(slots):
        i = slot
        while i < n:  # tasks slot, slot + slots, ...: equal shares in any order of the list
            tile = work.tasks[i]
            all_finite = 1
            all_inside = 1
            for cam in range(cams):
                win = camera_window(convert, centres, tile, cam)
                flags = window_flags(convert.padded, cam, win.oy, win.ox)
                all_finite *= win.finite * flags[0]
                all_inside *= win.inside * flags[1]  # featureless: not valid
                bx = axis_basis(win.sx)
                by = axis_basis(win.sy)
                for u in range(n_used):
                    colour = correlate.used[u]
                    g = forward_colour(convert.padded, cam, win.oy, win.ox, convert.masks,
                                       win.parity * n_colours + colour, bx, by)
                    store_clt(g, convert, kernel_base(convert, cam, win, colour), work.scratch,
                              slot * block + (cam * n_used + u) * 4)
            finite[tile] = ti.u8(all_finite)
            valid[tile] = ti.u8(all_finite * all_inside)
            if all_finite == 0:
                clear_tile(tile, npairs, corr, layers, with_layers)
            else:
                for p in range(npairs):
                    base_a = slot * block + correlate.pairs[p, 0] * n_used * 4
                    base_b = slot * block + correlate.pairs[p, 1] * n_used * 4
                    correlate_pair(work.scratch, base_a, base_b, work.positions, correlate, corr, tile * npairs + p)
                if with_layers != 0:
                    tile_layers(corr, tile, correlate.net_offset, layers)
            i += slots
