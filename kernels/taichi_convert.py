"""Taichi twin of kernels/convert.py: raw frames -> CLT tiles (tile_processor.md §1.4, §3-§5), one CPU thread
(or GPU thread) per tile, the tiles spread over every core.

The same math, arguments and layouts as the Warp kernel (see there): integer window pick from the pair-clamped
padded frame, per colour the Bayer mask, the forward MCLT as two separable products with the closed-form basis
of §3.1 / §13 (shifted half-sine window, fold, DCT-IV/DST-IV and the phase rotation in one 8x16 matrix per axis),
then the optional aberration-kernel product (§5.2). The per-camera pieces are ``ti.func``s that the split kernel
here and the fused kernel (kernels/taichi_fused.py) both call.

Speed (CPU): the basis of a shift s is built by angle addition from shift-free constant tables
(``operators.shifted_basis_parts``, compile-time constants): one sine and cosine per axis instead of 256. A colour's rows are streamed:
each image row's horizontal transform (only the columns of that colour's parity, the Bayer masks being 2-periodic
along a row) is added into the 16 x 16 result at once, so no intermediate tile is kept; rows without the colour
are skipped.

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8) = [tile, cam, colour, q]; bool masks are passed as uint8
views of the processor's bool tensors. The 16 x 16 product ``g`` of one colour is [vertical cos | sin,
horizontal cos | sin]: quadrant q = 2 (vertical sine) + (horizontal sine) is ``g[8 (q >> 1) + ky, 8 (q & 1) + kx]``.
"""

import taichi as ti

from tpnet_gpu import operators
from tpnet_gpu.kernels.frames import CENTRE_LIMIT, HALF_WINDOW, WINDOW
from tpnet_gpu.kernels.taichi_frames import window_corner
from tpnet_gpu.kernels.taichi_types import F32_3D, U8_1D, V8_2D
from tpnet_gpu.layout import FLOAT32_MAX, PIXEL_LIMIT
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis

_WINDOW_PARTS, _PHASE_PARTS = operators.shifted_basis_parts()
WINDOW_PARTS, PHASE_PARTS = _WINDOW_PARTS.tolist(), _PHASE_PARTS.tolist()  # compile-time constants
# [part][n][j], for basis_row: [cos | sin](phi_k(n) + a_k) = ROW_PARTS[0][n] [cos a | cos a]
#                                                            + ROW_PARTS[1][n] [sin a | sin a]
ROW_PARTS = (
    [[PHASE_PARTS[0][k][n] for k in range(N)] + [PHASE_PARTS[1][k][n] for k in range(N)] for n in range(WINDOW)],
    [[-PHASE_PARTS[1][k][n] for k in range(N)] + [PHASE_PARTS[0][k][n] for k in range(N)] for n in range(WINDOW)],
)

# The conversion's frames and tables, one pack per processor (kernels/convert.ConvertInputs without the bases'
# index tables: the bases are compile-time here): padded (cams, H + 2 PAD, W + 2 PAD) frames; image_height,
# image_width: H and W, px; colours (3 R, B, G; 1 mono); masks (4 * colours, 16, 16) [parity_y, parity_x, colour],
# 2-periodic along rows; kernels (cams * kernel_rows * kernel_cols * colours * 4, 8) rows of 8 (V8) of the
# aberration kernels [cam, node row, node col, colour, q, ky]; kernel_rows, kernel_cols: the 16-px kernel grid's
# nodes; use_kernels (0 / 1): multiply by them (§5.2).
ConvertInputs = ti.types.argpack(padded=F32_3D, image_height=ti.i32, image_width=ti.i32, colours=ti.i32,
                                 masks=F32_3D, kernels=V8_2D, kernel_rows=ti.i32, kernel_cols=ti.i32,
                                 use_kernels=ti.i32)
# Where one camera's window lies: padded-frame corner, residual shifts, Bayer parity, kernel-grid node, flags.
CameraWindow = ti.types.struct(oy=ti.i32, ox=ti.i32, sx=ti.f32, sy=ti.f32, parity=ti.i32, kny=ti.i32, knx=ti.i32,
                               finite=ti.i32, inside=ti.i32)


# --- element functions --------------------------------------------------------------------------------------
@ti.func
def is_finite(v: ti.f32) -> bool:
    return ti.abs(v) <= FLOAT32_MAX  # False for NaN and +-inf


@ti.func
def is_pixel(v: ti.f32) -> bool:
    """A pixel the products can take: finite and at most PIXEL_LIMIT in magnitude (False for NaN)."""
    return ti.abs(v) <= PIXEL_LIMIT


@ti.func
def kernel_node(position: ti.f32, nodes: ti.i32) -> ti.i32:
    """Nearest kernel-grid node (node n centred at pixel 16 n - 8), clamped to the grid."""
    return ti.math.clamp(ti.i32(ti.floor(position / 16.0)) + 1, 0, nodes - 1)


@ti.func
def camera_window(inputs: ti.template(), centres: ti.template(), tile: ti.i32, cam: ti.i32) -> CameraWindow:
    """The window of camera ``cam`` at ``tile`` (a non-finite centre reads at 0 and clears ``finite``)."""
    cx = centres[tile, cam, 0]
    cy = centres[tile, cam, 1]
    finite = 1
    if not (is_finite(cx) and is_finite(cy)):
        finite = 0
        cx = 0.0
        cy = 0.0
    px = ti.math.clamp(cx, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
    py = ti.math.clamp(cy, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
    itl_x = ti.i32(ti.floor(px + 0.5))
    itl_y = ti.i32(ti.floor(py + 0.5))
    height = inputs.image_height
    width = inputs.image_width
    inside = 1
    if itl_x < 0 or itl_y < 0 or itl_x + WINDOW > width or itl_y + WINDOW > height:
        inside = 0
    return CameraWindow(oy=window_corner(itl_y, height), ox=window_corner(itl_x, width),
                        sx=ti.cast(itl_x, ti.f32) - px, sy=ti.cast(itl_y, ti.f32) - py,
                        parity=(itl_y & 1) * 2 + (itl_x & 1), kny=kernel_node(cy, inputs.kernel_rows),
                        knx=kernel_node(cx, inputs.kernel_cols), finite=finite, inside=inside)


@ti.func
def axis_basis(s: ti.f32):
    """(16, 16) [n, j]: 1/2 w(n + s) cos(omega_k (n + s + 4.5)) for j = k < 8, the sine for j = 8 + k, by angle
    addition from the shift-free parts of ``operators.shifted_basis_parts`` (compile-time constants), a row at a
    time (``basis_row``)."""
    theta = ti.math.pi * s / 16.0
    c1 = ti.cos(theta)
    s1 = ti.sin(theta)
    c2 = c1 * c1 - s1 * s1  # rotation by 2 theta: cos / sin of (2k + 1) theta for k = 0..7 by recurrence
    s2 = 2.0 * s1 * c1
    ck = ti.Vector.zero(ti.f32, N)
    sk = ti.Vector.zero(ti.f32, N)
    ck[0] = c1
    sk[0] = s1
    for k in ti.static(range(1, N)):
        ck[k] = ck[k - 1] * c2 - sk[k - 1] * s2
        sk[k] = sk[k - 1] * c2 + ck[k - 1] * s2
    cos2 = ti.Vector([ck[j % N] for j in ti.static(range(WINDOW))])  # [cos | cos] of (2k + 1) theta
    sin2 = ti.Vector([sk[j % N] for j in ti.static(range(WINDOW))])
    return ti.Matrix.rows([basis_row(n, c1, s1, cos2, sin2) for n in ti.static(range(WINDOW))])


@ti.func
def basis_row(n: ti.template(), c1: ti.f32, s1: ti.f32, cos2: ti.template(), sin2: ti.template()):
    """Row n of ``axis_basis``: the shifted window's value times [cos | sin](phi_k(n) + (2k + 1) theta)."""
    half_w = 0.5 * (ti.static(WINDOW_PARTS[0][n]) * c1 + ti.static(WINDOW_PARTS[1][n]) * s1)
    cos_part = ti.Vector([ti.static(ROW_PARTS[0][n][j]) for j in ti.static(range(WINDOW))])
    sin_part = ti.Vector([ti.static(ROW_PARTS[1][n][j]) for j in ti.static(range(WINDOW))])
    return half_w * (cos_part * cos2 + sin_part * sin2)


@ti.func
def window_flags(padded: ti.template(), cam: ti.i32, oy: ti.i32, ox: ti.i32):
    """(finite, featured) of the 16 x 16 window at (oy, ox), one read per pixel: finite is 1 when every pixel is
    finite and at most PIXEL_LIMIT (``is_pixel``); featured is 1 unless every pixel (those failing ``is_pixel``
    read as 0) equals the first - a featureless window is not valid (as kernels/convert.convert_camera)."""
    first = padded[cam, oy, ox]
    first = ti.select(is_pixel(first), first, 0.0)
    finite = 1
    featured = 0
    for r in range(WINDOW):
        for c in ti.static(range(WINDOW)):
            v = padded[cam, oy + r, ox + c]
            ok = is_pixel(v)
            if not ok:
                finite = 0
            if ti.select(ok, v, 0.0) != first:
                featured = 1
    return ti.math.ivec2(finite, featured)


@ti.func
def forward_colour(padded: ti.template(), cam: ti.i32, oy: ti.i32, ox: ti.i32, masks: ti.template(), mask: ti.i32,
                   bx: ti.template(), by: ti.template()):
    """(16, 16) ``g`` of one colour (module docstring): sum over rows r of by[r, :]^T (x[r, :] bx), x the masked
    window; a row reads only the columns its mask weights (even, odd or both parities), non-finite pixels as 0."""
    g = [ti.Vector.zero(ti.f32, WINDOW) for _ in ti.static(range(WINDOW))]  # its rows, as vectors
    for r in range(WINDOW):
        w_even = masks[mask, r, 0]
        w_odd = masks[mask, r, 1]
        if w_even != 0.0 or w_odd != 0.0:
            t = ti.Vector.zero(ti.f32, WINDOW)  # horizontal transform of row r: [cos k | sin k]
            for phase in ti.static(range(2)):
                weight = masks[mask, r, phase]
                if weight != 0.0:
                    for j in ti.static(range(N)):
                        v = padded[cam, oy + r, ox + 2 * j + phase]
                        x = ti.select(is_pixel(v), weight * v, 0.0)
                        t += x * ti.Vector([bx[2 * j + phase, k] for k in ti.static(range(WINDOW))])
            for i in ti.static(range(WINDOW)):
                g[i] += by[r, i] * t
    return ti.Matrix.rows(g)


@ti.func
def store_clt(g: ti.template(), inputs: ti.template(), kb: ti.i32, dest: ti.template(), out: ti.i32):
    """Write ``g``'s 4 quadrants to dest[out + q], times the aberration kernel inputs.kernels[kb + q] (bicomplex,
    §5.2) when ``inputs.use_kernels``; ``dest`` and the kernels a row at a time (rows of 8 as vectors,
    taichi_types.V8)."""
    for ky in range(N):
        f0 = ti.Vector([g[ky, kx] for kx in ti.static(range(N))])  # CC
        f1 = ti.Vector([g[ky, N + kx] for kx in ti.static(range(N))])  # SC (horizontal sine)
        f2 = ti.Vector([g[N + ky, kx] for kx in ti.static(range(N))])  # CS (vertical sine)
        f3 = ti.Vector([g[N + ky, N + kx] for kx in ti.static(range(N))])  # SS
        if inputs.use_kernels:
            k0 = inputs.kernels[kb + 0, ky]
            k1 = inputs.kernels[kb + 1, ky]
            k2 = inputs.kernels[kb + 2, ky]
            k3 = inputs.kernels[kb + 3, ky]
            dest[out + 0, ky] = k0 * f0 - k1 * f1 - k2 * f2 + k3 * f3
            dest[out + 1, ky] = k0 * f1 + k1 * f0 - k2 * f3 - k3 * f2
            dest[out + 2, ky] = k0 * f2 + k2 * f0 - k1 * f3 - k3 * f1
            dest[out + 3, ky] = k0 * f3 + k3 * f0 + k1 * f2 + k2 * f1
        else:
            dest[out + 0, ky] = f0
            dest[out + 1, ky] = f1
            dest[out + 2, ky] = f2
            dest[out + 3, ky] = f3


@ti.func
def kernel_base(inputs: ti.template(), cam: ti.i32, win: ti.template(), colour: ti.i32) -> ti.i32:
    """First of the 4 kernel quadrants of (cam, the window's kernel-grid node, colour)."""
    return (((cam * inputs.kernel_rows + win.kny) * inputs.kernel_cols + win.knx) * inputs.colours + colour) * 4


# --- kernel -------------------------------------------------------------------------------------------------
@ti.kernel
def convert_tiles(inputs: ConvertInputs, centres: F32_3D, active: U8_1D, clt: V8_2D, finite: U8_1D, valid: U8_1D):
    """One thread per tile; arguments as kernels/convert.convert_tiles except the bases (built in the kernel from
    the compile-time parts of ``operators.shifted_basis_parts`` instead of the index tables) and the colours (all
    of ``inputs.colours``). finite/valid out: (tiles,) uint8."""
    cams = centres.shape[1]
    n_colours = inputs.colours  # (a pack's member names are reserved in a kernel: taichi_types.py)
    for tile in range(centres.shape[0]):
        all_finite = 1
        all_inside = 1
        if active[tile] == 0:
            all_finite = 0
            all_inside = 0
        else:
            for cam in range(cams):
                win = camera_window(inputs, centres, tile, cam)
                flags = window_flags(inputs.padded, cam, win.oy, win.ox)
                all_finite *= win.finite * flags[0]
                all_inside *= win.inside * flags[1]
                bx = axis_basis(win.sx)
                by = axis_basis(win.sy)
                for colour in range(n_colours):
                    mask = win.parity * n_colours + colour
                    g = forward_colour(inputs.padded, cam, win.oy, win.ox, inputs.masks, mask, bx, by)
                    store_clt(g, inputs, kernel_base(inputs, cam, win, colour), clt,
                              ((tile * cams + cam) * n_colours + colour) * 4)
        finite[tile] = ti.u8(all_finite)
        valid[tile] = ti.u8(all_finite * all_inside)
