"""Taichi twin of kernels/correlate.py: CLT tiles of camera pairs -> pixel-domain phase correlations
(tile_processor.md §6), and the network's 4 layers (network.md §1).

``correlate_pair`` (a ``ti.func``, called by the split kernel ``correlate_tiles`` here, one thread per (tile,
pair), and by the fused kernel in kernels/taichi_fused.py): per frequency the conjugate bicomplex product per
colour, the colour weights, the R+B low-pass, the fat-zero normalisation and the final low-pass; then the 8-point
DCT-II/DST-II per quadrant and the lag unfold as a signed gather into the (2r+1)^2 tile (the same operator as
the Warp kernel's two dense products); the spectrum is made row by row (``spectrum_row``), each row going
through its column-side transform at once, so it is never stored whole. ``network_layers`` (per element) combines the quad's pairs.

Speed (CPU): colours of zero weight are skipped (the caller passes the used colours); the 8-point transforms and
the columns' unfold are compile-time constants (``operators.half_dtt2e``, ``operators.unfold_gather``), and each 8-point
transform folds its input (x_k +- x_{7-k}, the matrices being (anti)symmetric in k with the parity of m), which
halves its multiplications.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8); ``corr`` (tiles * pairs, 15, 15); ``layers``
(tiles, 4, 9, 9); ``finite`` (tiles,) uint8. Spectra are held as one (16, 16) matrix [vertical cos | sin,
horizontal cos | sin] as in kernels/taichi_convert.py.
"""

import taichi as ti

from tpnet_gpu import operators
from tpnet_gpu.kernels.correlate import CORR_SIDE, NET_CROP
from tpnet_gpu.kernels.taichi_types import F32_1D, F32_2D, F32_3D, F32_4D, I32_1D, I32_2D, U8_1D, V8_1D, V8_2D
from tpnet_gpu.layout import FLOAT32_MAX, NET_LAYERS, NET_SIDE
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis

HALF_DTT2E = operators.half_dtt2e().tolist()  # [sine][m][k], compile-time constants
_INDEX, _SIGN = operators.unfold_gather()
UNFOLD_INDEX, UNFOLD_SIGN = _INDEX.tolist(), _SIGN.tolist()  # [sine][lag + 7]
HALF = N // 2


def lag_sign(q: int, r: int, c: int) -> float:
    """Sign of quadrant q's term at lag (r, c) of the unfold gather (the cosine parts' signs are +1)."""
    return (UNFOLD_SIGN[1][r] if q >> 1 else 1.0) * (UNFOLD_SIGN[1][c] if q & 1 else 1.0)


def lag_col(q: int, c: int) -> int:
    return N * (q & 1) + UNFOLD_INDEX[q & 1][c]


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
def spectrum_row(src: ti.template(), base_a: ti.i32, base_b: ti.i32, used: ti.template(), positions: ti.template(),
                 weights: ti.template(), has_rb: ti.i32, fat_zero: ti.f32, lpf_rb: ti.template(),
                 lpf_corr: ti.template(), ky: ti.i32):
    """(4, 8) [q, kx]: row ``ky`` of the normalised, low-passed correlation spectrum of the tiles at
    src[base_a + 4 positions[u] + q] and src[base_b + ...] over the used colours u (colour used[u], weight
    weights[u]); ``has_rb``: R or B is among them (their sum is low-passed before green is added, §6.2).
    ``src``, ``lpf_rb`` and ``lpf_corr`` are read a row at a time (rows of 8 as vectors, taichi_types.V8): the
    row's 8 frequencies are vector lanes throughout (the same arithmetic per frequency as one at a time)."""
    x0 = ti.Vector.zero(ti.f32, N)
    x1 = ti.Vector.zero(ti.f32, N)
    x2 = ti.Vector.zero(ti.f32, N)
    x3 = ti.Vector.zero(ti.f32, N)
    r0 = ti.Vector.zero(ti.f32, N)
    r1 = ti.Vector.zero(ti.f32, N)
    r2 = ti.Vector.zero(ti.f32, N)
    r3 = ti.Vector.zero(ti.f32, N)
    for u in range(used.shape[0]):
        ia = base_a + 4 * positions[u]
        ib = base_b + 4 * positions[u]
        w_rb = ti.select(has_rb != 0 and used[u] < 2, weights[u], 0.0)
        w = weights[u] - w_rb
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
        low = lpf_rb[ky]
        x0 = r0 * low + x0
        x1 = r1 * low + x1
        x2 = r2 * low + x2
        x3 = r3 * low + x3
    # The 8 norms as one vector (a packed 1/sqrt; ~7 % of a pass on CPU, tile_processor.md §10); the scaled
    # scalar form only where the unscaled squares could under- or overflow, NaN, or 0.
    energy = fat_zero * fat_zero + x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3
    inv = 1.0 / ti.sqrt(energy)
    for kx in ti.static(range(N)):
        if not (energy[kx] >= 1e-30 and energy[kx] <= 1e37):
            inv[kx] = inverse_norm(x0[kx], x1[kx], x2[kx], x3[kx], fat_zero)
    scale = inv * lpf_corr[ky]
    x = ti.Matrix.zero(ti.f32, 4, N)
    for kx in ti.static(range(N)):
        x[0, kx] = x0[kx] * scale[kx]
        x[1, kx] = x1[kx] * scale[kx]
        x[2, kx] = x2[kx] * scale[kx]
        x[3, kx] = x3[kx] * scale[kx]
    return x


@ti.func
def correlate_pair(src: ti.template(), base_a: ti.i32, base_b: ti.i32, used: ti.template(), positions: ti.template(),
                   weights: ti.template(), colours: ti.i32, fat_zero: ti.f32, lpf_rb: ti.template(),
                   lpf_corr: ti.template(), unfold_index: ti.template(), unfold_sign: ti.template(),
                   corr: ti.template(), out: ti.i32):
    """corr[out] (15, 15): the phase correlation of one pair = sum_q U_{q>>1} D_{q>>1} X_q D_{q&1}^T U_{q&1}^T,
    X the spectrum (``spectrum_row``), D the 8-point DCT-II-e / DST-II-e (x 1/2) on both sides, each on folded
    inputs, U the unfold as a signed gather (unfold_index / unfold_sign (2, 15), ``operators.unfold_gather``, for
    the rows; their constants for the columns). Each spectrum row goes through its column-side transform as it
    is made, so the spectrum is never stored whole."""
    has_rb = 0
    if colours == 3:
        for u in range(used.shape[0]):
            if used[u] < 2:
                has_rb = 1
    p = ti.Matrix.zero(ti.f32, 2 * N, 2 * N)  # P_q = X_q D_{q&1}^T (column side): p[8 (q >> 1) + ky, 8 (q & 1) + m]
    for ky in range(N):
        x = spectrum_row(src, base_a, base_b, used, positions, weights, has_rb, fat_zero, lpf_rb, lpf_corr, ky)
        for vs in ti.static(range(2)):
            acc = ti.Vector.zero(ti.f32, 2 * N)  # in registers: one store per element of p
            for hs in ti.static(range(2)):
                for k in ti.static(range(HALF)):
                    even = x[2 * vs + hs, k] + x[2 * vs + hs, N - 1 - k]
                    odd = x[2 * vs + hs, k] - x[2 * vs + hs, N - 1 - k]
                    for m in ti.static(range(0, N, 2)):
                        acc[N * hs + m] += ti.static(HALF_DTT2E[hs][m][k]) * even
                        acc[N * hs + m + 1] += ti.static(HALF_DTT2E[hs][m + 1][k]) * odd
            for j in ti.static(range(2 * N)):
                p[N * vs + ky, j] = acc[j]
    y = ti.Matrix.zero(ti.f32, 2 * N, 2 * N)  # Y_q = D_{q>>1} P_q (row side): y[8 (q >> 1) + m, col]
    for col in range(2 * N):
        acc = ti.Vector.zero(ti.f32, 2 * N)
        for vs in ti.static(range(2)):
            for k in ti.static(range(HALF)):
                even = p[N * vs + k, col] + p[N * vs + N - 1 - k, col]
                odd = p[N * vs + k, col] - p[N * vs + N - 1 - k, col]
                for m in ti.static(range(0, N, 2)):
                    acc[N * vs + m] += ti.static(HALF_DTT2E[vs][m][k]) * even
                    acc[N * vs + m + 1] += ti.static(HALF_DTT2E[vs][m + 1][k]) * odd
        for j in ti.static(range(2 * N)):
            y[j, col] = acc[j]
    # The column unfold first (per row of Y: cosine part + signed sine part, 15 columns), then the rows gather.
    a = ti.Matrix.zero(ti.f32, 2 * N, CORR_SIDE)
    for row in range(2 * N):
        for c in ti.static(range(CORR_SIDE)):
            a[row, c] = y[row, ti.static(lag_col(0, c))]
            if ti.static(lag_sign(1, 0, c) != 0.0):  # the sine part is 0 at lag 0
                a[row, c] += ti.static(lag_sign(1, 0, c)) * y[row, ti.static(lag_col(1, c))]
    for r in range(CORR_SIDE):
        row_c = unfold_index[0, r]
        row_s = N + unfold_index[1, r]
        sign_r = unfold_sign[1, r]  # the cosine parts' signs are +1
        for c in ti.static(range(CORR_SIDE)):
            corr[out, r, c] = a[row_c, c] + sign_r * a[row_s, c]


@ti.func
def zero_correlations(corr: ti.template(), first: ti.i32, count: ti.i32):
    for i in range(first, first + count):
        for r in range(CORR_SIDE):
            for c in range(CORR_SIDE):
                corr[i, r, c] = 0.0


@ti.kernel
def correlate_tiles(
    clt: V8_2D,
    finite: U8_1D,
    pairs: I32_2D,
    cams: ti.i32,
    colours: ti.i32,
    used: I32_1D,
    weights: F32_1D,
    fat_zero: ti.f32,
    lpf_rb: V8_1D,
    lpf_corr: V8_1D,
    unfold_index: I32_2D,
    unfold_sign: F32_2D,
    corr: F32_3D,
):
    """One thread per (tile, pair); arguments as kernels/correlate.correlate_tiles except the colours: used
    (U,) the colours of non-zero weight, weights (U,) theirs; the inverse transform: the 8-point matrices as
    compile-time constants and unfold_index / unfold_sign (2, 15) (``operators.unfold_gather``). corr out: (tiles * P, 15, 15), zero for tiles whose CLT is not finite."""
    npairs = pairs.shape[0]
    for tile, p in ti.ndrange(finite.shape[0], npairs):
        out = tile * npairs + p
        if finite[tile] == 0:
            zero_correlations(corr, out, 1)
        else:
            base_a = (tile * cams + pairs[p, 0]) * colours * 4
            base_b = (tile * cams + pairs[p, 1]) * colours * 4
            correlate_pair(clt, base_a, base_b, used, used, weights, colours, fat_zero, lpf_rb, lpf_corr, unfold_index,
                           unfold_sign, corr, out)


@ti.func
def combine(a: ti.f32, b: ti.f32, offset: ti.f32) -> ti.f32:
    """sqrt((a + o)(b + o)) - o where both are positive, else 0; o < 0: the plain mean (network.md §1)."""
    out = 0.0
    if offset < 0.0:
        out = 0.5 * (a + b)
    elif a > 0.0 and b > 0.0:
        out = ti.sqrt((a + offset) * (b + offset)) - offset
    return out


@ti.func
def layer_value(corr: ti.template(), tile: ti.i32, layer: ti.i32, row: ti.i32, col: ti.i32, offset: ti.f32):
    """Element (row, col) of network layer ``layer`` of ``tile``: the 9x9 centre crop of [combine(pair 0,
    pair 1), combine(pair 2, pair 3), pair 4, pair 5] of the quad's pairs in the spec's order."""
    y = row + NET_CROP
    x = col + NET_CROP
    base = tile * 6
    value = 0.0
    if layer == 0:
        value = combine(corr[base + 0, y, x], corr[base + 1, y, x], offset)
    elif layer == 1:
        value = combine(corr[base + 2, y, x], corr[base + 3, y, x], offset)
    else:
        value = corr[base + layer + 2, y, x]
    return value


@ti.func
def tile_layers(corr: ti.template(), tile: ti.i32, offset: ti.f32, layers: ti.template()):
    """layers[tile] (4, 9, 9) from the tile's 6 correlations."""
    for layer in range(NET_LAYERS):
        for row in range(NET_SIDE):
            for col in range(NET_SIDE):
                layers[tile, layer, row, col] = layer_value(corr, tile, layer, row, col, offset)


@ti.kernel
def network_layers(corr: F32_3D, offset: ti.f32, layers: F32_4D):
    """corr: (tiles * 6, 15, 15) quad pairs in the spec's order; layers out: (tiles, 4, 9, 9) centre crops of
    [combine(pair 0, pair 1), combine(pair 2, pair 3), pair 4, pair 5]."""
    for tile, layer, row, col in layers:
        layers[tile, layer, row, col] = layer_value(corr, tile, layer, row, col, offset)
