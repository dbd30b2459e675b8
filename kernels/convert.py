"""Convert: raw frames -> frequency-domain (CLT) tiles, one thread block per tile (tile_processor.md §1.4, §3-§5).

For each camera of a tile: integer window pick from the pair-clamped padded frame, then per colour the Bayer
mask, and the forward MCLT as two small matrix products per quadrant with the closed-form basis of §3.1 /
§13 (shifted half-sine window, fold, DCT-IV/DST-IV and the phase rotation by the residual s in one 8x16
matrix per axis), then the optional aberration-kernel product (bicomplex, §5.2; it commutes with the rotation).

Layouts: ``clt`` is (tiles * cams * colours * 4, 8, 8) = [tile, cam, colour, q] flattened (Warp arrays have at
most 4 dimensions; torch views it as (tiles, cams, colours, 4, 8, 8)).
"""

import warp as wp

from tpnet_gpu.kernels.frames import CENTRE_LIMIT, HALF_WINDOW, window_corner
from tpnet_gpu.layout import PIXEL_LIMIT
from tpnet_gpu.runtime.warp_setup import kernel_module_options

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)


# --- arguments ------------------------------------------------------------------------------------------------
@wp.struct
class ConvertInputs:
    """What converting a camera's window reads besides the tile centres: one processor's padded frames and tables,
    built once with its buffers (the split and the fused kernels take the same one).

    Fields:
        padded: (cams, H + 2 PAD, W + 2 PAD) the pair-clamped padded frames (kernels/frames.py).
        image_height, image_width: H and W, pixels.
        colours: colours of the frames (3 Bayer R, B, G; 1 mono).
        masks: (4 * colours, 16, 16) colour masks [parity_y, parity_x, colour].
        k_rows, n_rows: (8, 16) the frequency k and the pixel n of each element of the vertical basis.
        n_cols, k_cols: (16, 8) the same for the horizontal basis.
        kernels: (cams * kernel_rows * kernel_cols * colours * 4, 8, 8) aberration kernels in CLT form
            [cam, node row, node col, colour, q] (a zero placeholder when ``use_kernels`` is False).
        kernel_rows, kernel_cols: nodes of the 16-px kernel grid.
        use_kernels: multiply by the kernels (§5.2).
    """

    padded: wp.array3d(dtype=wp.float32)
    image_height: int
    image_width: int
    colours: int
    masks: wp.array3d(dtype=wp.float32)
    k_rows: wp.array2d(dtype=wp.float32)
    n_rows: wp.array2d(dtype=wp.float32)
    n_cols: wp.array2d(dtype=wp.float32)
    k_cols: wp.array2d(dtype=wp.float32)
    kernels: wp.array3d(dtype=wp.float32)
    kernel_rows: int
    kernel_cols: int
    use_kernels: bool


# --- element functions --------------------------------------------------------------------------------------
@wp.func
def basis_cos(k: float, n: float, s: float) -> float:
    """1/2 w(n + s) cos(omega_k (n + s + 4.5)); the integer part of the phase is reduced exactly mod 2 pi."""
    whole = wp.mod((2.0 * k + 1.0) * (2.0 * n + 9.0), 64.0)
    angle = wp.pi * whole / 32.0 + wp.pi * (2.0 * k + 1.0) * s / 16.0
    return 0.5 * wp.sin(wp.pi * (2.0 * (n + s) + 1.0) / 32.0) * wp.cos(angle)


@wp.func
def basis_sin(k: float, n: float, s: float) -> float:
    """1/2 w(n + s) sin(omega_k (n + s + 4.5))."""
    whole = wp.mod((2.0 * k + 1.0) * (2.0 * n + 9.0), 64.0)
    angle = wp.pi * whole / 32.0 + wp.pi * (2.0 * k + 1.0) * s / 16.0
    return 0.5 * wp.sin(wp.pi * (2.0 * (n + s) + 1.0) / 32.0) * wp.sin(angle)


@wp.func
def finite_or_zero(v: float) -> float:
    """A pixel, or 0 where it is not finite or beyond PIXEL_LIMIT (the comparison is False for NaN)."""
    if wp.abs(v) <= PIXEL_LIMIT:
        return v
    return 0.0


@wp.func
def abs_difference(a: float, b: float) -> float:
    return wp.abs(a - b)


@wp.func
def non_finite(v: float) -> float:
    """1 where a pixel is not finite or beyond PIXEL_LIMIT, else 0."""
    if wp.abs(v) <= PIXEL_LIMIT:
        return 0.0
    return 1.0


# Bicomplex product K * F per frequency (§5.2), one function per output quadrant.
@wp.func
def kmul_cc(k0: float, k1: float, k2: float, k3: float, f0: float, f1: float, f2: float, f3: float) -> float:
    return k0 * f0 - k1 * f1 - k2 * f2 + k3 * f3


@wp.func
def kmul_sc(k0: float, k1: float, k2: float, k3: float, f0: float, f1: float, f2: float, f3: float) -> float:
    return k0 * f1 + k1 * f0 - k2 * f3 - k3 * f2


@wp.func
def kmul_cs(k0: float, k1: float, k2: float, k3: float, f0: float, f1: float, f2: float, f3: float) -> float:
    return k0 * f2 + k2 * f0 - k1 * f3 - k3 * f1


@wp.func
def kmul_ss(k0: float, k1: float, k2: float, k3: float, f0: float, f1: float, f2: float, f3: float) -> float:
    return k0 * f3 + k3 * f0 + k1 * f2 + k2 * f1


@wp.func
def kernel_node(position: float, nodes: int) -> int:
    """Nearest kernel-grid node (node n centred at pixel 16 n - 8), clamped to the grid."""
    return wp.clamp(int(wp.floor(position / 16.0)) + 1, 0, nodes - 1)


@wp.func
def convert_camera(
    inputs: ConvertInputs,
    centres: wp.array3d(dtype=wp.float32),
    tile: int,
    cam: int,
    colour_list: wp.array(dtype=wp.int32),
    dest: wp.array3d(dtype=wp.float32),
    dest_base: int,
):
    """Camera ``cam``'s window of ``tile``, converted for the colours colour_list[u] into dest[dest_base + 4 u + q]
    (the split kernel: every colour into the CLT buffer; the fused one: the used colours into its scratch).
    Returns (finite: every pixel and the centre finite, measurable: the window wholly inside the image and not
    featureless - not all of its (zero-filled) pixels equal: a clipped highlight or flat field has no feature to
    correlate, and at 16-bit levels its correlation is float32 rounding noise; tile_processor.md §6.7)."""
    finite = bool(True)
    inside = bool(True)
    cx = centres[tile, cam, 0]
    cy = centres[tile, cam, 1]
    if not (wp.isfinite(cx) and wp.isfinite(cy)):
        finite = False
        cx = 0.0
        cy = 0.0
    px = wp.clamp(cx, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
    py = wp.clamp(cy, -CENTRE_LIMIT, CENTRE_LIMIT) - float(HALF_WINDOW)
    itl_x = int(wp.floor(px + 0.5))
    itl_y = int(wp.floor(py + 0.5))
    sx = float(itl_x) - px
    sy = float(itl_y) - py
    if itl_x < 0 or itl_y < 0 or itl_x + 16 > inputs.image_width or itl_y + 16 > inputs.image_height:
        inside = False
    oy = window_corner(itl_y, inputs.image_height)
    ox = window_corner(itl_x, inputs.image_width)
    window = wp.tile_load(inputs.padded[cam], shape=(16, 16), offset=(oy, ox))
    bad = wp.tile_sum(wp.tile_map(non_finite, window))
    if wp.tile_extract(bad, 0) > 0.0:
        finite = False
    window = wp.tile_map(finite_or_zero, window)
    first = wp.tile_full(shape=(16, 16), value=wp.tile_extract(window, 0, 0), dtype=wp.float32)
    spread = wp.tile_sum(wp.tile_map(abs_difference, window, first))
    if wp.tile_extract(spread, 0) == 0.0:
        inside = False
    # Per-axis bases: rows (8, 16) for the vertical transform, transposed (16, 8) for the horizontal one.
    k_rows = inputs.k_rows  # a struct's array is loaded as a tile from a local (Warp 1.19: not from the field)
    n_rows = inputs.n_rows
    n_cols = inputs.n_cols
    k_cols = inputs.k_cols
    kr = wp.tile_load(k_rows, shape=(8, 16))
    nr = wp.tile_load(n_rows, shape=(8, 16))
    nc = wp.tile_load(n_cols, shape=(16, 8))
    kc = wp.tile_load(k_cols, shape=(16, 8))
    v_cos = wp.tile_map(basis_cos, kr, nr, wp.tile_full(shape=(8, 16), value=sy, dtype=wp.float32))
    v_sin = wp.tile_map(basis_sin, kr, nr, wp.tile_full(shape=(8, 16), value=sy, dtype=wp.float32))
    h_cos = wp.tile_map(basis_cos, kc, nc, wp.tile_full(shape=(16, 8), value=sx, dtype=wp.float32))
    h_sin = wp.tile_map(basis_sin, kc, nc, wp.tile_full(shape=(16, 8), value=sx, dtype=wp.float32))
    parity = (itl_y & 1) * 2 + (itl_x & 1)
    kny = kernel_node(cy, inputs.kernel_rows)
    knx = kernel_node(cx, inputs.kernel_cols)
    for u in range(colour_list.shape[0]):
        colour = colour_list[u]
        mask = wp.tile_load(inputs.masks[parity * inputs.colours + colour], shape=(16, 16))
        x = wp.tile_map(wp.mul, window, mask)
        t_cos = wp.tile_matmul(x, h_cos)  # (16, 8): horizontal cosine transform of every row
        t_sin = wp.tile_matmul(x, h_sin)
        f0 = wp.tile_matmul(v_cos, t_cos)  # CC
        f1 = wp.tile_matmul(v_cos, t_sin)  # SC
        f2 = wp.tile_matmul(v_sin, t_cos)  # CS
        f3 = wp.tile_matmul(v_sin, t_sin)  # SS
        out = dest_base + 4 * u
        if inputs.use_kernels:
            kb = (((cam * inputs.kernel_rows + kny) * inputs.kernel_cols + knx) * inputs.colours + colour) * 4
            k0 = wp.tile_load(inputs.kernels[kb + 0], shape=(8, 8))
            k1 = wp.tile_load(inputs.kernels[kb + 1], shape=(8, 8))
            k2 = wp.tile_load(inputs.kernels[kb + 2], shape=(8, 8))
            k3 = wp.tile_load(inputs.kernels[kb + 3], shape=(8, 8))
            wp.tile_store(dest[out + 0], wp.tile_map(kmul_cc, k0, k1, k2, k3, f0, f1, f2, f3))
            wp.tile_store(dest[out + 1], wp.tile_map(kmul_sc, k0, k1, k2, k3, f0, f1, f2, f3))
            wp.tile_store(dest[out + 2], wp.tile_map(kmul_cs, k0, k1, k2, k3, f0, f1, f2, f3))
            wp.tile_store(dest[out + 3], wp.tile_map(kmul_ss, k0, k1, k2, k3, f0, f1, f2, f3))
        else:
            wp.tile_store(dest[out + 0], f0)
            wp.tile_store(dest[out + 1], f1)
            wp.tile_store(dest[out + 2], f2)
            wp.tile_store(dest[out + 3], f3)
    return finite, inside  # inside: also featured (docstring)


# --- kernel -------------------------------------------------------------------------------------------------
@wp.kernel
def convert_tiles(
    inputs: ConvertInputs,
    centres: wp.array3d(dtype=wp.float32),
    active: wp.array(dtype=wp.bool),
    colour_list: wp.array(dtype=wp.int32),
    clt: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    valid: wp.array(dtype=wp.bool),
):
    """One block per tile. inputs: the frames and tables (``ConvertInputs``); centres: (tiles, cams, 2);
    colour_list: (colours,) 0..colours-1; clt out as in the module docstring; finite/valid: (tiles,) - finite:
    every window and centre finite (else the tile's CLT is zero); valid: finite, active and every window wholly
    inside the image (else its pixels were read pair-clamped) and not featureless (``convert_camera``)."""
    tile = wp.tid()
    if not active[tile]:
        finite[tile] = False
        valid[tile] = False
        return
    cams = centres.shape[1]
    colours = colour_list.shape[0]
    all_finite = bool(True)
    all_inside = bool(True)
    for cam in range(cams):
        cam_finite, cam_inside = convert_camera(inputs, centres, tile, cam, colour_list, clt,
                                                (tile * cams + cam) * colours * 4)
        all_finite = all_finite and cam_finite
        all_inside = all_inside and cam_inside
    finite[tile] = all_finite
    valid[tile] = all_finite and all_inside
