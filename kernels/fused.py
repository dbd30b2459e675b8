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

Layouts: the task list, the scratch and the ``written`` flags as ``FusedWork``; the rest as convert.py and
correlate.py, whose argument structs (``ConvertInputs``, ``CorrelateInputs``) ``fused_tiles`` takes as they do.
"""

import warp as wp

from tpnet_gpu.kernels.convert import ConvertInputs, convert_camera
from tpnet_gpu.kernels.correlate import CorrelateInputs, correlate_pair, zero_correlations
from tpnet_gpu.runtime.warp_setup import kernel_module_options

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)


@wp.struct
class FusedWork:
    """The fused pass's own buffers, built once when the backend allocates its scratch.

    Fields:
        tasks: (tiles,) int32 the active tiles (``compact_tasks``); count: (1,) int32 how many.
        slots: thread blocks of the launch (its dim), each with its own part of the scratch.
        positions: (U,) int32 the places 0..U-1 of the used colours in the scratch.
        scratch: (slots * cams * U * 4, 8, 8) [slot, cam, used colour, q] one tile's spectra per slot.
        written: (tiles,) bool the tiles whose correlations an earlier pass may have left non-zero.
    """

    tasks: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    slots: int
    positions: wp.array(dtype=wp.int32)
    scratch: wp.array3d(dtype=wp.float32)
    written: wp.array(dtype=wp.bool)


@wp.kernel
def reset_count(work: FusedWork):
    work.count[0] = 0


@wp.kernel
def compact_tasks(
    active: wp.array(dtype=wp.bool),
    npairs: int,
    work: FusedWork,
    finite: wp.array(dtype=wp.bool),
    valid: wp.array(dtype=wp.bool),
    corr: wp.array3d(dtype=wp.float32),
):
    """Per tile: append an active tile to ``work.tasks`` (and mark it ``written``); an inactive one gets
    finite/valid False and zero correlations (zeroed only if ``written``, which it then clears)."""
    written = work.written
    tile = wp.tid()
    if active[tile]:
        work.tasks[wp.atomic_add(work.count, 0, 1)] = tile
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
    work: FusedWork,
    convert: ConvertInputs,
    centres: wp.array3d(dtype=wp.float32),
    correlate: CorrelateInputs,
    corr: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    valid: wp.array(dtype=wp.bool),
):
    """Launched with dim ``work.slots``; the other arguments as convert_tiles and correlate_tiles."""
    slot = wp.tid()
    cams = centres.shape[1]
    npairs = correlate.pairs.shape[0]
    n_used = correlate.used.shape[0]
    block = slot * cams * n_used * 4
    i = slot
    while i < work.count[0]:
        tile = work.tasks[i]
        all_finite = bool(True)
        all_inside = bool(True)
        for cam in range(cams):
            cam_finite, cam_inside = convert_camera(convert, centres, tile, cam, correlate.used, work.scratch,
                                                    block + cam * n_used * 4)
            all_finite = all_finite and cam_finite
            all_inside = all_inside and cam_inside
        finite[tile] = all_finite
        valid[tile] = all_finite and all_inside
        if all_finite:
            for p in range(npairs):
                base_a = block + correlate.pairs[p, 0] * n_used * 4
                base_b = block + correlate.pairs[p, 1] * n_used * 4
                correlate_pair(work.scratch, base_a, base_b, work.positions, correlate, corr, tile * npairs + p)
        else:
            zero_correlations(corr, tile * npairs, npairs)
        i += work.slots
