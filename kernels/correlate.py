"""Correlate: CLT tiles of camera pairs -> pixel-domain phase correlations (tile_processor.md §6), and the
network's 4 layers (network.md §1).

``correlate_tiles``, one block per tile, for every pair: the conjugate bicomplex product per colour, colour
weights, the R+B low-pass, the fat-zero normalisation, the final low-pass, then DCT-II/DST-II and the lag unfold
as two matrix products per quadrant into a (2r+1)^2 tile. ``network_layers`` (per thread) combines the quad's
pairs into [hor, vert, diag-main, diag-other] 9x9 crops.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8); ``corr`` (tiles * pairs, 2r+1, 2r+1); ``layers``
(tiles, 4, 9, 9) (Warp arrays have at most 4 dimensions; torch views the flat ones with their full shape).
"""

import warp as wp

from tpnet_gpu.layout import FLOAT32_MAX
from tpnet_gpu.runtime.warp_setup import kernel_module_options

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)

CORR_SIDE = 15  # 2 r + 1 with r = 7 (lag +-8 is dropped)
NET_SIDE = 9
NET_CROP = (CORR_SIDE - NET_SIDE) // 2


# --- arguments ------------------------------------------------------------------------------------------------
@wp.struct
class CorrelateInputs:
    """What correlating a tile's pairs reads besides the spectra: one processor's pairs, colour weights and
    tables, built once with its buffers (the split and the fused kernels take the same one).

    Fields:
        pairs: (P, 2) camera indices (first, second) of each pair.
        colours: colours of the spectra (3 R, B, G; 1 mono).
        used, weights: (U,) the colours of non-zero weight (ascending) and their weights.
        fat_zero: the fat zero of the normalisation (§6.2).
        lpf_rb, lpf_corr: (8, 8) the R + B low-pass and the final one.
        lags_cos, lags_sin: (15, 8) 1/2 x lag unfold x DCT-II-e / DST-II-e; freqs_cos, freqs_sin: (8, 15) their
            transposes.
    """

    pairs: wp.array2d(dtype=wp.int32)
    colours: int
    used: wp.array(dtype=wp.int32)
    weights: wp.array(dtype=wp.float32)
    fat_zero: float
    lpf_rb: wp.array2d(dtype=wp.float32)
    lpf_corr: wp.array2d(dtype=wp.float32)
    lags_cos: wp.array2d(dtype=wp.float32)
    lags_sin: wp.array2d(dtype=wp.float32)
    freqs_cos: wp.array2d(dtype=wp.float32)
    freqs_sin: wp.array2d(dtype=wp.float32)


# conj(A) * B per frequency (§6.2), one function per output quadrant.
@wp.func
def xcorr_cc(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float) -> float:
    return a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3


@wp.func
def xcorr_sc(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float) -> float:
    return a0 * b1 - a1 * b0 + a2 * b3 - a3 * b2


@wp.func
def xcorr_cs(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float) -> float:
    return a0 * b2 - a2 * b0 + a1 * b3 - a3 * b1


@wp.func
def xcorr_ss(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float) -> float:
    return a0 * b3 + a3 * b0 - a1 * b2 - a2 * b1


@wp.func
def inverse_norm(x0: float, x1: float, x2: float, x3: float, fat_zero: float) -> float:
    """1 / sqrt(fz^2 + sum_q X_q^2), or 0 where that is 0 (fz = 0 and no energy at this frequency). Computed as
    r / sqrt(sum (x r)^2) with r = 1 / max(fz, |X_q|): the squares of large products would overflow float32
    (issue 16: pixels >= 1e11 gave all-zero correlations) and those of small ones underflow."""
    m = wp.max(wp.max(wp.max(wp.abs(x0), wp.abs(x1)), wp.max(wp.abs(x2), wp.abs(x3))), fat_zero)
    if m > 0.0 and m <= FLOAT32_MAX:
        r = 1.0 / m
        f, a, b, c, d = fat_zero * r, x0 * r, x1 * r, x2 * r, x3 * r
        return r / wp.sqrt(f * f + a * a + b * b + c * c + d * d)
    return 0.0


@wp.func
def mul3(a: float, b: float, c: float) -> float:
    return a * b * c


@wp.func
def axpy(w: float, x: float, y: float) -> float:
    return w * x + y


@wp.func
def correlate_pair(
    src: wp.array3d(dtype=wp.float32),
    base_a: int,
    base_b: int,
    positions: wp.array(dtype=wp.int32),
    inputs: CorrelateInputs,
    corr: wp.array3d(dtype=wp.float32),
    out: int,
):
    """corr[out] (15, 15): the phase correlation of the tiles at src[base_a + 4 positions[u] + q] and
    src[base_b + ...] over the used colours u (colour inputs.used[u] of inputs.colours, weight
    inputs.weights[u])."""
    used = inputs.used
    lpf_rb = inputs.lpf_rb  # a struct's array is loaded as a tile from a local (Warp 1.19: not from the field)
    lpf_corr = inputs.lpf_corr
    lags_cos = inputs.lags_cos
    lags_sin = inputs.lags_sin
    freqs_cos = inputs.freqs_cos
    freqs_sin = inputs.freqs_sin
    x0 = wp.tile_zeros(shape=(8, 8), dtype=wp.float32)
    x1 = wp.tile_zeros(shape=(8, 8), dtype=wp.float32)
    x2 = wp.tile_zeros(shape=(8, 8), dtype=wp.float32)
    x3 = wp.tile_zeros(shape=(8, 8), dtype=wp.float32)
    for u in range(used.shape[0]):
        ia = base_a + 4 * positions[u]
        ib = base_b + 4 * positions[u]
        a0 = wp.tile_load(src[ia + 0], shape=(8, 8))
        a1 = wp.tile_load(src[ia + 1], shape=(8, 8))
        a2 = wp.tile_load(src[ia + 2], shape=(8, 8))
        a3 = wp.tile_load(src[ia + 3], shape=(8, 8))
        b0 = wp.tile_load(src[ib + 0], shape=(8, 8))
        b1 = wp.tile_load(src[ib + 1], shape=(8, 8))
        b2 = wp.tile_load(src[ib + 2], shape=(8, 8))
        b3 = wp.tile_load(src[ib + 3], shape=(8, 8))
        w = wp.tile_full(shape=(8, 8), value=inputs.weights[u], dtype=wp.float32)
        x0 = wp.tile_map(axpy, w, wp.tile_map(xcorr_cc, a0, a1, a2, a3, b0, b1, b2, b3), x0)
        x1 = wp.tile_map(axpy, w, wp.tile_map(xcorr_sc, a0, a1, a2, a3, b0, b1, b2, b3), x1)
        x2 = wp.tile_map(axpy, w, wp.tile_map(xcorr_cs, a0, a1, a2, a3, b0, b1, b2, b3), x2)
        x3 = wp.tile_map(axpy, w, wp.tile_map(xcorr_ss, a0, a1, a2, a3, b0, b1, b2, b3), x3)
        # R and B accumulated: their low-pass (§6.2), before green (the last colour) is added
        next_colour = 2
        if u + 1 < used.shape[0]:
            next_colour = used[u + 1]
        if inputs.colours == 3 and used[u] < 2 and next_colour == 2:
            rb = wp.tile_load(lpf_rb, shape=(8, 8))
            x0 = wp.tile_map(wp.mul, x0, rb)
            x1 = wp.tile_map(wp.mul, x1, rb)
            x2 = wp.tile_map(wp.mul, x2, rb)
            x3 = wp.tile_map(wp.mul, x3, rb)
    lc = wp.tile_load(lpf_corr, shape=(8, 8))
    fat_zero = wp.tile_full(shape=(8, 8), value=inputs.fat_zero, dtype=wp.float32)
    scale = wp.tile_map(inverse_norm, x0, x1, x2, x3, fat_zero)
    x0 = wp.tile_map(mul3, x0, scale, lc)
    x1 = wp.tile_map(mul3, x1, scale, lc)
    x2 = wp.tile_map(mul3, x2, scale, lc)
    x3 = wp.tile_map(mul3, x3, scale, lc)
    # Back to lags: R = sum_q L_{q>>1} X_q L_{q&1}^T (rows: vertical sine iff q>>1; columns: sine iff q&1).
    lag_c = wp.tile_load(lags_cos, shape=(CORR_SIDE, 8))
    lag_s = wp.tile_load(lags_sin, shape=(CORR_SIDE, 8))
    frq_c = wp.tile_load(freqs_cos, shape=(8, CORR_SIDE))
    frq_s = wp.tile_load(freqs_sin, shape=(8, CORR_SIDE))
    result = wp.tile_zeros(shape=(CORR_SIDE, CORR_SIDE), dtype=wp.float32)
    wp.tile_matmul(lag_c, wp.tile_matmul(x0, frq_c), result)
    wp.tile_matmul(lag_c, wp.tile_matmul(x1, frq_s), result)
    wp.tile_matmul(lag_s, wp.tile_matmul(x2, frq_c), result)
    wp.tile_matmul(lag_s, wp.tile_matmul(x3, frq_s), result)
    wp.tile_store(corr[out], result)


@wp.func
def zero_correlations(corr: wp.array3d(dtype=wp.float32), first: int, count: int):
    for i in range(count):
        wp.tile_store(corr[first + i], wp.tile_zeros(shape=(CORR_SIDE, CORR_SIDE), dtype=wp.float32))


@wp.kernel
def correlate_tiles(
    clt: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    cams: int,
    inputs: CorrelateInputs,
    corr: wp.array3d(dtype=wp.float32),
):
    """One block per tile. inputs: the pairs, colours and tables (``CorrelateInputs``); corr out: (tiles * P, 15,
    15), zero for tiles whose CLT is not finite."""
    tile = wp.tid()
    npairs = inputs.pairs.shape[0]
    if not finite[tile]:
        zero_correlations(corr, tile * npairs, npairs)
        return
    per_cam = inputs.colours * 4
    for p in range(npairs):
        base_a = (tile * cams + inputs.pairs[p, 0]) * per_cam
        base_b = (tile * cams + inputs.pairs[p, 1]) * per_cam
        # the CLT holds every colour: colour used[u] is at place used[u]
        correlate_pair(clt, base_a, base_b, inputs.used, inputs, corr, tile * npairs + p)


@wp.func
def combine(a: float, b: float, offset: float) -> float:
    """sqrt((a + o)(b + o)) - o where both are positive, else 0; o < 0: the plain mean (network.md §1)."""
    if offset < 0.0:
        return 0.5 * (a + b)
    if a > 0.0 and b > 0.0:
        return wp.sqrt((a + offset) * (b + offset)) - offset
    return 0.0


@wp.kernel
def network_layers(corr: wp.array3d(dtype=wp.float32), offset: float, layers: wp.array4d(dtype=wp.float32)):
    """corr: (tiles * 6, 15, 15) quad pairs in the spec's order; layers out: (tiles, 4, 9, 9) centre crops of
    [combine(pair 0, pair 1), combine(pair 2, pair 3), pair 4, pair 5]."""
    tile, layer, row, col = wp.tid()
    y = row + NET_CROP
    x = col + NET_CROP
    base = tile * 6
    value = float(0.0)
    if layer == 0:
        value = combine(corr[base + 0, y, x], corr[base + 1, y, x], offset)
    elif layer == 1:
        value = combine(corr[base + 2, y, x], corr[base + 3, y, x], offset)
    else:
        value = corr[base + layer + 2, y, x]
    layers[tile, layer, row, col] = value
