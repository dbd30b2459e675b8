"""Taichi twin of kernels/correlate.py: CLT tiles of camera pairs -> pixel-domain phase correlations
(tile_processor.md §6), and the network's 4 layers (network.md §1).

``correlate_tiles``, one thread per (tile, pair), spread over every core: per frequency the conjugate bicomplex
product per colour, the colour weights, the R+B low-pass, the fat-zero normalisation and the final low-pass; then
the 8-point DCT-II/DST-II per quadrant and the lag unfold as a signed gather into the (2r+1)^2 tile (the same
operator as the Warp kernel's two dense products, at a quarter of the multiplications). ``network_layers``
(per element) combines the quad's pairs. Same arguments, tables and layouts as the Warp kernels.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8); ``corr`` (tiles * pairs, 15, 15); ``layers``
(tiles, 4, 9, 9); ``finite`` (tiles,) uint8.
"""

import taichi as ti

from tpnet_gpu.kernels.correlate import CORR_SIDE, NET_CROP
from tpnet_gpu.kernels.taichi_types import F32_1D, F32_2D, F32_3D, F32_4D, I32_2D, U8_1D
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis


@ti.func
def inverse_norm(x0: ti.f32, x1: ti.f32, x2: ti.f32, x3: ti.f32, fat_zero: ti.f32) -> ti.f32:
    """1 / sqrt(fz^2 + sum_q X_q^2), or 0 where that is 0 (fz = 0 and no energy at this frequency)."""
    n2 = fat_zero * fat_zero + x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3
    out = 0.0
    if n2 > 0.0:
        out = 1.0 / ti.sqrt(n2)
    return out


@ti.kernel
def correlate_tiles(
    clt: F32_3D,
    finite: U8_1D,
    pairs: I32_2D,
    cams: ti.i32,
    colours: ti.i32,
    colour_weights: F32_1D,
    fat_zero: ti.f32,
    lpf_rb: F32_2D,
    lpf_corr: F32_2D,
    dtt2e: F32_3D,
    unfold_index: I32_2D,
    unfold_sign: F32_2D,
    corr: F32_3D,
):
    """One thread per (tile, pair); arguments as kernels/correlate.correlate_tiles except the inverse transform:
    dtt2e (2, 8, 8) = 1/2 x [DCT-II-e, DST-II-e] [m, k] and unfold_index / unfold_sign (2, 15) [cos/sin, lag + 7]:
    the one index each lag reads and its sign (0: lag 0 of the sine part), both from tables (the Warp kernel's
    lags_* = 1/2 x unfold x DCT-II-e as dense products). corr out: (tiles * P, 15, 15), zero for tiles whose CLT
    is not finite."""
    npairs = pairs.shape[0]
    for tile, p in ti.ndrange(finite.shape[0], npairs):
        out = tile * npairs + p
        if finite[tile] == 0:
            for r, c in ti.ndrange(CORR_SIDE, CORR_SIDE):
                corr[out, r, c] = 0.0
        else:
            x0 = ti.Matrix.zero(ti.f32, N, N)  # CC
            x1 = ti.Matrix.zero(ti.f32, N, N)  # SC
            x2 = ti.Matrix.zero(ti.f32, N, N)  # CS
            x3 = ti.Matrix.zero(ti.f32, N, N)  # SS
            for ky in range(N):
                for kx in ti.static(range(N)):
                    s0 = 0.0
                    s1 = 0.0
                    s2 = 0.0
                    s3 = 0.0
                    for colour in range(colours):
                        ia = ((tile * cams + pairs[p, 0]) * colours + colour) * 4
                        ib = ((tile * cams + pairs[p, 1]) * colours + colour) * 4
                        a0 = clt[ia + 0, ky, kx]
                        a1 = clt[ia + 1, ky, kx]
                        a2 = clt[ia + 2, ky, kx]
                        a3 = clt[ia + 3, ky, kx]
                        b0 = clt[ib + 0, ky, kx]
                        b1 = clt[ib + 1, ky, kx]
                        b2 = clt[ib + 2, ky, kx]
                        b3 = clt[ib + 3, ky, kx]
                        w = colour_weights[colour]  # conj(A) * B per frequency (§6.2)
                        s0 = w * (a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3) + s0
                        s1 = w * (a0 * b1 - a1 * b0 + a2 * b3 - a3 * b2) + s1
                        s2 = w * (a0 * b2 - a2 * b0 + a1 * b3 - a3 * b1) + s2
                        s3 = w * (a0 * b3 + a3 * b0 - a1 * b2 - a2 * b1) + s3
                        if colours == 3 and colour == 1:  # R and B accumulated: their low-pass (§6.2)
                            rb = lpf_rb[ky, kx]
                            s0 *= rb
                            s1 *= rb
                            s2 *= rb
                            s3 *= rb
                    scale = inverse_norm(s0, s1, s2, s3, fat_zero) * lpf_corr[ky, kx]
                    x0[ky, kx] = s0 * scale
                    x1[ky, kx] = s1 * scale
                    x2[ky, kx] = s2 * scale
                    x3[ky, kx] = s3 * scale
            # Back to lags: R = sum_q U_{q>>1} D_{q>>1} X_q D_{q&1}^T U_{q&1}^T with the 8-point DCT-II-e / DST-II-e
            # D (x 1/2) and the lag unfold U, one signed index per lag: Y_q = D X_q D^T, then R gathers from Y.
            p0 = ti.Matrix.zero(ti.f32, N, N)  # P_q = X_q D_{q&1}^T (column side)
            p1 = ti.Matrix.zero(ti.f32, N, N)
            p2 = ti.Matrix.zero(ti.f32, N, N)
            p3 = ti.Matrix.zero(ti.f32, N, N)
            for m in range(N):
                for ky in ti.static(range(N)):
                    for kx in ti.static(range(N)):
                        dc = dtt2e[0, m, kx]
                        ds = dtt2e[1, m, kx]
                        p0[ky, m] += x0[ky, kx] * dc
                        p1[ky, m] += x1[ky, kx] * ds
                        p2[ky, m] += x2[ky, kx] * dc
                        p3[ky, m] += x3[ky, kx] * ds
            y0 = ti.Matrix.zero(ti.f32, N, N)  # Y_q = D_{q>>1} P_q (row side)
            y1 = ti.Matrix.zero(ti.f32, N, N)
            y2 = ti.Matrix.zero(ti.f32, N, N)
            y3 = ti.Matrix.zero(ti.f32, N, N)
            for m in range(N):
                for ky in ti.static(range(N)):
                    dc = dtt2e[0, m, ky]
                    ds = dtt2e[1, m, ky]
                    for c in ti.static(range(N)):
                        y0[m, c] += dc * p0[ky, c]
                        y1[m, c] += dc * p1[ky, c]
                        y2[m, c] += ds * p2[ky, c]
                        y3[m, c] += ds * p3[ky, c]
            for r in range(CORR_SIDE):
                rc = unfold_index[0, r]
                rs = unfold_index[1, r]
                sr = unfold_sign[1, r]
                for c in range(CORR_SIDE):
                    cc = unfold_index[0, c]
                    cs = unfold_index[1, c]
                    sc = unfold_sign[1, c]
                    corr[out, r, c] = y0[rc, cc] + sc * y1[rc, cs] + sr * y2[rs, cc] + sr * sc * y3[rs, cs]


@ti.func
def combine(a: ti.f32, b: ti.f32, offset: ti.f32) -> ti.f32:
    """sqrt((a + o)(b + o)) - o where both are positive, else 0; o < 0: the plain mean (network.md §1)."""
    out = 0.0
    if offset < 0.0:
        out = 0.5 * (a + b)
    elif a > 0.0 and b > 0.0:
        out = ti.sqrt((a + offset) * (b + offset)) - offset
    return out


@ti.kernel
def network_layers(corr: F32_3D, offset: ti.f32, layers: F32_4D):
    """corr: (tiles * 6, 15, 15) quad pairs in the spec's order; layers out: (tiles, 4, 9, 9) centre crops of
    [combine(pair 0, pair 1), combine(pair 2, pair 3), pair 4, pair 5]."""
    for tile, layer, row, col in layers:
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
        layers[tile, layer, row, col] = value
