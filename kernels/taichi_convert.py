"""Taichi twin of kernels/convert.py: raw frames -> CLT tiles (tile_processor.md §1.4, §3-§5), one CPU thread
(or GPU thread) per tile, the tiles spread over every core.

The same math, arguments and layouts as the Warp kernel (see there): integer window pick from the pair-clamped
padded frame, per colour the Bayer mask, the forward MCLT as two separable products with the closed-form basis
of §3.1 / §13 (shifted half-sine window, fold, DCT-IV/DST-IV and the phase rotation in one 8x16 matrix per axis),
then the optional aberration-kernel product (§5.2). Masked-out pixels (zero mask) are skipped, so a Bayer colour
costs a quarter (R, B) or a half (G) of the row products.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8) = [tile, cam, colour, q]; bool masks are passed as uint8
views of the processor's bool tensors.
"""

import taichi as ti

from tpnet_gpu.kernels.frames import CENTRE_LIMIT, HALF_WINDOW, WINDOW
from tpnet_gpu.kernels.taichi_frames import window_corner
from tpnet_gpu.kernels.taichi_types import F32_3D, U8_1D
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis


# --- element functions --------------------------------------------------------------------------------------
@ti.func
def basis_angle(k: ti.i32, n: ti.i32, s: ti.f32) -> ti.f32:
    """omega_k (n + s + 4.5) with the integer part of the phase reduced exactly mod 2 pi (as the Warp basis)."""
    whole = ((2 * k + 1) * (2 * n + 9)) % 64
    return ti.math.pi * ti.cast(whole, ti.f32) / 32.0 + ti.math.pi * ti.cast(2 * k + 1, ti.f32) * s / 16.0


@ti.func
def half_window(n: ti.i32, s: ti.f32) -> ti.f32:
    """1/2 w(n + s), the shifted half-sine window."""
    return 0.5 * ti.sin(ti.math.pi * (2.0 * (ti.cast(n, ti.f32) + s) + 1.0) / 32.0)


@ti.func
def is_finite(v: ti.f32) -> bool:
    return ti.abs(v) <= 3.4028234e38  # False for NaN and +-inf


@ti.func
def kernel_node(position: ti.f32, nodes: ti.i32) -> ti.i32:
    """Nearest kernel-grid node (node n centred at pixel 16 n - 8), clamped to the grid."""
    return ti.math.clamp(ti.i32(ti.floor(position / 16.0)) + 1, 0, nodes - 1)


# --- kernel -------------------------------------------------------------------------------------------------
@ti.kernel
def convert_tiles(
    padded: F32_3D,
    centres: F32_3D,
    active: U8_1D,
    masks: F32_3D,
    kernels: F32_3D,
    kernel_rows: ti.i32,
    kernel_cols: ti.i32,
    use_kernels: ti.i32,
    image_height: ti.i32,
    image_width: ti.i32,
    colours: ti.i32,
    clt: F32_3D,
    finite: U8_1D,
    valid: U8_1D,
):
    """One thread per tile; arguments as kernels/convert.convert_tiles (the index tables are not needed: the
    bases are evaluated in place). finite/valid out: (tiles,) uint8."""
    cams = centres.shape[1]
    for tile in range(centres.shape[0]):
        all_finite = 1
        all_inside = 1
        if active[tile] == 0:
            all_finite = 0
            all_inside = 0
        else:
            for cam in range(cams):
                cx = centres[tile, cam, 0]
                cy = centres[tile, cam, 1]
                if not (is_finite(cx) and is_finite(cy)):
                    all_finite = 0
                    cx = 0.0
                    cy = 0.0
                px = ti.math.clamp(cx, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
                py = ti.math.clamp(cy, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
                itl_x = ti.i32(ti.floor(px + 0.5))
                itl_y = ti.i32(ti.floor(py + 0.5))
                sx = ti.cast(itl_x, ti.f32) - px
                sy = ti.cast(itl_y, ti.f32) - py
                if itl_x < 0 or itl_y < 0 or itl_x + WINDOW > image_width or itl_y + WINDOW > image_height:
                    all_inside = 0
                oy = window_corner(itl_y, image_height)
                ox = window_corner(itl_x, image_width)
                for r, c in ti.ndrange(WINDOW, WINDOW):
                    if not is_finite(padded[cam, oy + r, ox + c]):
                        all_finite = 0
                # Per-axis bases: h_* [n, kx] for the horizontal transform, v_* [ky, n] for the vertical one.
                h_cos = ti.Matrix.zero(ti.f32, WINDOW, N)
                h_sin = ti.Matrix.zero(ti.f32, WINDOW, N)
                v_cos = ti.Matrix.zero(ti.f32, N, WINDOW)
                v_sin = ti.Matrix.zero(ti.f32, N, WINDOW)
                for n in range(WINDOW):
                    wx = half_window(n, sx)
                    wy = half_window(n, sy)
                    for k in ti.static(range(N)):
                        ax = basis_angle(k, n, sx)
                        ay = basis_angle(k, n, sy)
                        h_cos[n, k] = wx * ti.cos(ax)
                        h_sin[n, k] = wx * ti.sin(ax)
                        v_cos[k, n] = wy * ti.cos(ay)
                        v_sin[k, n] = wy * ti.sin(ay)
                parity = (itl_y & 1) * 2 + (itl_x & 1)
                kny = kernel_node(cy, kernel_rows)
                knx = kernel_node(cx, kernel_cols)
                for colour in range(colours):
                    mask = parity * colours + colour
                    # Horizontal transform of every row: t_* [row, kx] = sum_m x[row, m] h_*[m, kx].
                    t_cos = ti.Matrix.zero(ti.f32, WINDOW, N)
                    t_sin = ti.Matrix.zero(ti.f32, WINDOW, N)
                    for r in range(WINDOW):
                        for c in range(WINDOW):
                            weight = masks[mask, r, c]
                            if weight != 0.0:
                                v = padded[cam, oy + r, ox + c]
                                if not is_finite(v):
                                    v = 0.0
                                x = weight * v
                                for k in ti.static(range(N)):
                                    t_cos[r, k] += x * h_cos[c, k]
                                    t_sin[r, k] += x * h_sin[c, k]
                    out = ((tile * cams + cam) * colours + colour) * 4
                    kb = (((cam * kernel_rows + kny) * kernel_cols + knx) * colours + colour) * 4
                    for ky in range(N):
                        f0 = ti.Vector.zero(ti.f32, N)  # CC
                        f1 = ti.Vector.zero(ti.f32, N)  # SC (horizontal sine)
                        f2 = ti.Vector.zero(ti.f32, N)  # CS (vertical sine)
                        f3 = ti.Vector.zero(ti.f32, N)  # SS
                        for r in range(WINDOW):
                            vc = v_cos[ky, r]
                            vs = v_sin[ky, r]
                            for k in ti.static(range(N)):
                                f0[k] += vc * t_cos[r, k]
                                f1[k] += vc * t_sin[r, k]
                                f2[k] += vs * t_cos[r, k]
                                f3[k] += vs * t_sin[r, k]
                        for k in ti.static(range(N)):
                            if use_kernels:  # bicomplex product K * F (§5.2)
                                k0 = kernels[kb + 0, ky, k]
                                k1 = kernels[kb + 1, ky, k]
                                k2 = kernels[kb + 2, ky, k]
                                k3 = kernels[kb + 3, ky, k]
                                clt[out + 0, ky, k] = k0 * f0[k] - k1 * f1[k] - k2 * f2[k] + k3 * f3[k]
                                clt[out + 1, ky, k] = k0 * f1[k] + k1 * f0[k] - k2 * f3[k] - k3 * f2[k]
                                clt[out + 2, ky, k] = k0 * f2[k] + k2 * f0[k] - k1 * f3[k] - k3 * f1[k]
                                clt[out + 3, ky, k] = k0 * f3[k] + k3 * f0[k] + k1 * f2[k] + k2 * f1[k]
                            else:
                                clt[out + 0, ky, k] = f0[k]
                                clt[out + 1, ky, k] = f1[k]
                                clt[out + 2, ky, k] = f2[k]
                                clt[out + 3, ky, k] = f3[k]
        finite[tile] = ti.u8(all_finite)
        valid[tile] = ti.u8(all_finite * all_inside)
