"""Taichi twin of kernels/correlate.py: CLT tiles of camera pairs -> pixel-domain phase correlations
(tile_processor.md §6), and the network's 4 layers (network.md §1).

``correlate_pair`` (a ``ti.func``, called by the split kernel ``correlate_tiles`` here, one thread per (tile,
pair), and by the fused kernel in kernels/taichi_fused.py): per frequency the conjugate bicomplex product per
colour, the colour weights, the R+B low-pass, the fat-zero normalisation and the final low-pass; then the 8-point
DCT-II/DST-II per quadrant and the lag unfold as a signed gather into the (2r+1)^2 tile (the same operator as
the Warp kernel's two dense products); the spectrum is made row by row (``spectrum_row``), each row going
through its column-side transform at once, so it is never stored whole. ``network_layers`` (per tile, a row at a
time) combines the quad's pairs.

Speed (CPU): colours of zero weight are skipped (the caller passes the used colours); the 8-point transforms and
the unfold are compile-time constants (``operators.half_dtt2e``, ``operators.unfold_gather``); rows are vectors
(Taichi keeps them as LLVM vectors, taichi_setup.py): a transform is a sum of constant rows or columns times
scalars, the packed instructions the CPU has. The row side folds its input rows (P_k +- P_{7-k}, the matrices
being even or odd in k with the parity of m), which halves its vector products.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8); ``corr`` (tiles * pairs, 15, 15) and ``layers`` (tiles, 4, 9,
9), both passed flat (a vector type of 15 or 9 lanes would make Taichi emit aligned vector accesses at unaligned
rows); ``finite`` (tiles,) uint8.
"""

import taichi as ti

from tpnet_gpu import operators
from tpnet_gpu.kernels.correlate import CORR_SIDE, NET_CROP
from tpnet_gpu.kernels.taichi_types import F32_1D, I32_1D, I32_2D, U8_1D, V8_1D, V8_2D
from tpnet_gpu.layout import FLOAT32_MAX, NET_LAYERS, NET_SIDE
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis

HALF_DTT2E = operators.half_dtt2e().tolist()  # [sine][m][k], compile-time constants
_INDEX, _SIGN = operators.unfold_gather()
UNFOLD_INDEX, UNFOLD_SIGN = _INDEX.tolist(), _SIGN.tolist()  # [sine][lag + 7]
HALF = N // 2

# The correlation's pairs, colours and settings, one pack per processor (kernels/correlate.CorrelateInputs without
# the transforms' tables: compile-time constants here): pairs (P, 2) camera indices (first, second); colours (3 R,
# B, G; 1 mono); used, weights (U,) the colours of non-zero weight (ascending) and their weights; fat_zero (§6.2);
# lpf_rb, lpf_corr (8,) rows of 8 (V8) of the R + B and the final low-pass; net_offset: the network layers' pair
# combination (``combine``; the fused kernel makes the layers).
CorrelateInputs = ti.types.argpack(pairs=I32_2D, colours=ti.i32, used=I32_1D, weights=F32_1D, fat_zero=ti.f32,
                                   lpf_rb=V8_1D, lpf_corr=V8_1D, net_offset=ti.f32)


@ti.func
def inverse_norm(x0: ti.f32, x1: ti.f32, x2: ti.f32, x3: ti.f32, fat_zero: ti.f32) -> ti.f32:
    """1 / sqrt(fz^2 + sum_q X_q^2), or 0 where that is 0; scaled by r = 1 / max(fz, |X_q|) first, as the Warp
    kernel (kernels/correlate.py: no overflow of the squares of large products)."""
    m = ti.max(ti.abs(x0), ti.abs(x1), ti.abs(x2), ti.abs(x3), fat_zero)
    out = 0.0
    if m > 0.0 and m <= FLOAT32_MAX:
        r = 1.0 / m
        f, a, b, c, d = fat_zero * r, x0 * r, x1 * r, x2 * r, x3 * r
        out = r / ti.sqrt(f * f + a * a + b * b + c * c + d * d)
    return out


@ti.func
def spectrum_row(src: ti.template(), base_a: ti.i32, base_b: ti.i32, positions: ti.template(), inputs: ti.template(),
                 has_rb: ti.i32, ky: ti.i32):
    """(4, 8) [q, kx]: row ``ky`` of the normalised, low-passed correlation spectrum of the tiles at
    src[base_a + 4 positions[u] + q] and src[base_b + ...] over the used colours u (colour inputs.used[u], weight
    inputs.weights[u]); ``has_rb``: R or B is among them (their sum is low-passed before green is added, §6.2).
    ``src`` and the low-passes are read a row at a time (rows of 8 as vectors, taichi_types.V8): the row's 8
    frequencies are vector lanes throughout (the same arithmetic per frequency as one at a time)."""
    x0 = ti.Vector.zero(ti.f32, N)
    x1 = ti.Vector.zero(ti.f32, N)
    x2 = ti.Vector.zero(ti.f32, N)
    x3 = ti.Vector.zero(ti.f32, N)
    r0 = ti.Vector.zero(ti.f32, N)
    r1 = ti.Vector.zero(ti.f32, N)
    r2 = ti.Vector.zero(ti.f32, N)
    r3 = ti.Vector.zero(ti.f32, N)
    for u in range(inputs.used.shape[0]):
        ia = base_a + 4 * positions[u]
        ib = base_b + 4 * positions[u]
        w_rb = ti.select(has_rb != 0 and inputs.used[u] < 2, inputs.weights[u], 0.0)
        w = inputs.weights[u] - w_rb
        a0, a1, a2, a3 = src[ia + 0, ky], src[ia + 1, ky], src[ia + 2, ky], src[ia + 3, ky]
        b0, b1, b2, b3 = src[ib + 0, ky], src[ib + 1, ky], src[ib + 2, ky], src[ib + 3, ky]
        p0 = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3  # conj(A) * B per frequency (§6.2)
        p1 = a0 * b1 - a1 * b0 + a2 * b3 - a3 * b2
        p2 = a0 * b2 - a2 * b0 + a1 * b3 - a3 * b1
        p3 = a0 * b3 + a3 * b0 - a1 * b2 - a2 * b1
        x0 += w * p0
        x1 += w * p1
        x2 += w * p2
        x3 += w * p3
        if has_rb != 0:
            r0 += w_rb * p0
            r1 += w_rb * p1
            r2 += w_rb * p2
            r3 += w_rb * p3
    if has_rb != 0:  # without R and B this adds 0 * lpf_rb: skipped
        low = inputs.lpf_rb[ky]
        x0 = r0 * low + x0
        x1 = r1 * low + x1
        x2 = r2 * low + x2
        x3 = r3 * low + x3
    # The 8 norms as one vector (a packed 1/sqrt; ~7 % of a pass on CPU, tile_processor.md §10); the scaled
    # scalar form only where the unscaled squares could under- or overflow, NaN, or 0.
    fat_zero = inputs.fat_zero
    energy = fat_zero * fat_zero + x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3
    inv = 1.0 / ti.sqrt(energy)
    # 1 / 0 per lane, 0 for NaN (as integers: Taichi 1.7 misreads single lanes, any() and all() of a comparison's
    # vector when matrices are LLVM vectors; selects of it are right)
    usual = ti.select((energy >= 1e-30) & (energy <= 1e37), 1, 0)
    if usual.min() == 0:  # one test per row in the usual case
        for kx in ti.static(range(N)):
            if usual[kx] == 0:
                inv[kx] = inverse_norm(x0[kx], x1[kx], x2[kx], x3[kx], fat_zero)
    scale = inv * inputs.lpf_corr[ky]
    return ti.Matrix.rows([x0 * scale, x1 * scale, x2 * scale, x3 * scale])


@ti.func
def dtt2e_column(sine: ti.template(), k: ti.template()):
    """Column k of the 1/2 DCT-II-e (sine 0) or DST-II-e (sine 1) as a constant vector over m."""
    return ti.Vector([ti.static(HALF_DTT2E[sine][m][k]) for m in ti.static(range(N))])


@ti.func
def correlate_pair(src: ti.template(), base_a: ti.i32, base_b: ti.i32, positions: ti.template(), inputs: ti.template(),
                   corr: ti.template(), out: ti.i32):
    """corr[out] (15 x 15, flat): the phase correlation of one pair = sum_q U_{q>>1} D_{q>>1} X_q D_{q&1}^T
    U_{q&1}^T, X the spectrum (``spectrum_row``), D the 8-point DCT-II-e / DST-II-e (x 1/2) on both sides, U the
    unfold as a signed gather (``operators.unfold_gather``). Rows are vectors throughout: each spectrum row goes
    through its column-side transform (a sum of constant columns of D times the row's frequencies) as it is made,
    so the spectrum is never stored; the row side sums constant multiples of the folded rows of P_q."""
    has_rb = 0
    if inputs.colours == 3:
        for u in range(inputs.used.shape[0]):
            if inputs.used[u] < 2:
                has_rb = 1
    # p[q][ky]: row ky of P_q = X_q D_{q&1}^T, a vector over the column-side frequency (a row-indexed matrix: ky
    # is a loop variable; unrolling that loop made the kernel compile 4x longer for 5 % speed)
    p = [ti.Matrix.zero(ti.f32, N, N) for _ in ti.static(range(4))]
    for ky in range(N):
        x = spectrum_row(src, base_a, base_b, positions, inputs, has_rb, ky)
        for q in ti.static(range(4)):
            row = ti.Vector.zero(ti.f32, N)
            for kx in ti.static(range(N)):
                row += x[q, kx] * dtt2e_column(q & 1, kx)
            for m in ti.static(range(N)):
                p[q][ky, m] = row[m]
    # y[q][m]: row m of Y_q = D_{q>>1} P_q, on folded rows (the matrices are even in k <-> 7 - k for even m, odd for
    # odd m: half the products)
    y = [[ti.Vector.zero(ti.f32, N) for _ in ti.static(range(N))] for _ in ti.static(range(4))]
    for q in ti.static(range(4)):
        rows = [ti.Vector([p[q][k, m] for m in ti.static(range(N))]) for k in ti.static(range(N))]
        for k in ti.static(range(HALF)):
            even = rows[k] + rows[N - 1 - k]
            odd = rows[k] - rows[N - 1 - k]
            for m in ti.static(range(0, N, 2)):
                y[q][m] += ti.static(HALF_DTT2E[q >> 1][m][k]) * even
                y[q][m + 1] += ti.static(HALF_DTT2E[q >> 1][m + 1][k]) * odd
    # The rows' unfold (cosine part + signed sine part), then each row's columns gathered the same way.
    for r in ti.static(range(CORR_SIDE)):
        half = [y[hs][ti.static(UNFOLD_INDEX[0][r])] for hs in ti.static(range(2))]
        if ti.static(UNFOLD_SIGN[1][r] != 0.0):  # the sine part is 0 at lag 0
            for hs in ti.static(range(2)):
                half[hs] += ti.static(UNFOLD_SIGN[1][r]) * y[2 + hs][ti.static(UNFOLD_INDEX[1][r])]
        first = (out * CORR_SIDE + r) * CORR_SIDE
        for c in ti.static(range(CORR_SIDE)):
            value = half[0][ti.static(UNFOLD_INDEX[0][c])]
            if ti.static(UNFOLD_SIGN[1][c] != 0.0):
                value += ti.static(UNFOLD_SIGN[1][c]) * half[1][ti.static(UNFOLD_INDEX[1][c])]
            corr[first + c] = value


@ti.func
def zero_correlations(corr: ti.template(), first: ti.i32, count: ti.i32):
    for i in range(first * CORR_SIDE * CORR_SIDE, (first + count) * CORR_SIDE * CORR_SIDE):
        corr[i] = 0.0


@ti.kernel
def correlate_tiles(clt: V8_2D, finite: U8_1D, cams: ti.i32, inputs: CorrelateInputs, corr: F32_1D):
    """One thread per (tile, pair); arguments as kernels/correlate.correlate_tiles; the inverse transform and the
    lag unfold are compile-time constants (``operators.half_dtt2e``, ``operators.unfold_gather``). corr out: (tiles
    * P, 15, 15) flat, zero for tiles whose CLT is not finite."""
    npairs = inputs.pairs.shape[0]
    per_cam = inputs.colours * 4
    for tile, p in ti.ndrange(finite.shape[0], npairs):
        out = tile * npairs + p
        if finite[tile] == 0:
            zero_correlations(corr, out, 1)
        else:
            base_a = (tile * cams + inputs.pairs[p, 0]) * per_cam
            base_b = (tile * cams + inputs.pairs[p, 1]) * per_cam
            # the CLT holds every colour: colour used[u] is at place used[u]
            correlate_pair(clt, base_a, base_b, inputs.used, inputs, corr, out)


@ti.func
def combine(a: ti.template(), b: ti.template(), offset: ti.f32):
    """Per lane: sqrt((a + o)(b + o)) - o where both are positive, else 0; o < 0: the plain mean (network.md §1)."""
    out = 0.5 * (a + b)
    if offset >= 0.0:
        both = (a > 0.0) & (b > 0.0)
        out = ti.select(both, ti.sqrt(ti.max((a + offset) * (b + offset), 0.0)) - offset, 0.0)
    return out


@ti.func
def crop(corr: ti.template(), pair: ti.i32, row: ti.i32):
    """The centre NET_SIDE lags of row ``row`` of the (flat) correlation ``pair``, as a vector."""
    first = (pair * CORR_SIDE + row + NET_CROP) * CORR_SIDE + NET_CROP
    return ti.Vector([corr[first + c] for c in ti.static(range(NET_SIDE))])


@ti.func
def tile_layers(corr: ti.template(), tile: ti.i32, offset: ti.f32, layers: ti.template()):
    """layers[tile] (4, 9, 9), flat: the centre crops of [combine(pair 0, pair 1), combine(pair 2, pair 3),
    pair 4, pair 5] of the tile's 6 correlations (the quad's pairs in the spec's order), a row at a time."""
    base = tile * 6
    for row in range(NET_SIDE):
        rows = [combine(crop(corr, base + 0, row), crop(corr, base + 1, row), offset),
                combine(crop(corr, base + 2, row), crop(corr, base + 3, row), offset),
                crop(corr, base + 4, row), crop(corr, base + 5, row)]
        for layer in ti.static(range(NET_LAYERS)):
            first = ((tile * NET_LAYERS + layer) * NET_SIDE + row) * NET_SIDE
            for c in ti.static(range(NET_SIDE)):
                layers[first + c] = rows[layer][c]


@ti.kernel
def network_layers(corr: F32_1D, offset: ti.f32, layers: F32_1D):
    """corr: (tiles * 6, 15, 15) quad pairs in the spec's order; layers out: (tiles, 4, 9, 9) (``tile_layers``);
    both flat."""
    for tile in range(layers.shape[0] // (NET_LAYERS * NET_SIDE * NET_SIDE)):
        tile_layers(corr, tile, offset, layers)
