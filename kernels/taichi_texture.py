"""Taichi twin of kernels/texture.py: shift-corrected CLT tiles -> RGBA image with alpha from the cameras'
agreement (tile_processor.md §7.3, §7.4), spread over every core.

The same math, tables and layouts as the Warp module (see there), in three launches shaped for CPU threads:
``texture_imclt`` (one thread per tile, camera and colour: low-pass and inverse MCLT as two matrix products per
quadrant, then the demosaic filter and compression of its rows as soon as the next row exists - the Warp
module's ``texture_imclt`` + ``texture_demosaic``), ``texture_combine`` (per run of ``LANES`` pixels of one
band's tiles, the pixels as vector lanes: camera weights in registers, colour, alpha and the alpha fade, written
straight into the tile's slot of the ``rgba`` ring; its exponentials by ``exp_f32``, within ~1 ulp of libm's),
``overlap_add`` (per canvas pixel, fixed order, no atomics). ``cams`` and ``colours`` are compile-time
(``ti.template``): one kernel per rig shape, loops over cameras unrolled. Bool masks are uint8 views;
``offsets`` is (cams, 2); ``inv_window2`` is 1 / W2 (16, 16).
"""

import taichi as ti

from tpnet_gpu import operators
from tpnet_gpu.kernels.taichi_types import F32_1D, F32_2D, F32_3D, I32_1D, U8_1D
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis
from tpnet_gpu.tables import TILE_SIZE as SIDE  # window side, pixels

# (2, 16, 8) the inverse operators (the values Buffers uploads as inv_cos, inv_sin) as compile-time constants:
# the column products, unrolled, fold them into the instructions (measured: IMCLT -22 %); the row products
# index them by a loop variable and read the uploaded tables.
INVERSE = operators.inverse_axes().astype("float32").tolist()


# texture_imclt reads and writes whole rows (CLT rows of 8, pixel rows of 16) as vectors: one vector load or store
# each instead of 8 or 16 scalar ones the compiler then packs (measured: texture_imclt -9 %). The arrays keep their
# (n, 8, 8) and (n, 16, 16) shapes: the last axis is the vector.
ROW8 = ti.types.ndarray(dtype=ti.types.vector(N, ti.f32), ndim=2)
ROW16 = ti.types.ndarray(dtype=ti.types.vector(SIDE, ti.f32), ndim=2)
ROW16_1D = ti.types.ndarray(dtype=ti.types.vector(SIDE, ti.f32), ndim=1)

# texture_combine: one thread per run of LANES pixels of a tile row, the run's pixels as vector lanes. Straight-line
# lane code (selects instead of branches, exp_f32 instead of the libm call) lets the compiler turn each step into
# LANES-wide vector instructions: the camera weights' ten exponentials per pixel were most of the combine's time
# (measured: 4 lanes -25 %; 2 lanes gain nothing). With Taichi's matrices kept as LLVM vectors (taichi_setup.py),
# 8 lanes take 0.66x the time of 4 (5 MPix combine 0.53 -> 0.35 s); 16 lanes crash (rows of 64 bytes at 32-byte
# offsets: the vector loads assume alignment).
LANES = 8
RUNS = ti.types.ndarray(dtype=ti.types.vector(LANES, ti.f32), ndim=3)  # (n, 16, 16 / LANES) runs of pixels
RUNS_2D = ti.types.ndarray(dtype=ti.types.vector(LANES, ti.f32), ndim=2)  # (16, 16 / LANES)

# The texture's grid, settings and tables, one pack per processor (kernels/texture.TextureInputs without cams and
# colours, compile-time here, and the transposed operators): tiles_x, tiles_y: the frame's tile grid; ring_rows:
# tile rows of the ``rgba`` ring; lpf (colours, 8) rows of 8 of each colour's low-pass; inv_cos, inv_sin (16, 8)
# the inverse operators; inv_window2 (16,) rows of 16 of 1 / W2; scale_shot, min_shot: the shot-noise compression;
# offsets (cams, 2) the cameras' offsets in baselines; colour_weights (colours,); channel_of_colour (colours,)
# int32 output channels; diff_sigma, weight_floor (§7.3); dust_remove (0 / 1); output_gain; window2 (16, 16 /
# LANES) runs of W2.
TextureInputs = ti.types.argpack(tiles_x=ti.i32, tiles_y=ti.i32, ring_rows=ti.i32, lpf=ROW8, inv_cos=F32_2D,
                                 inv_sin=F32_2D, inv_window2=ROW16_1D, scale_shot=ti.f32, min_shot=ti.f32,
                                 offsets=F32_2D, colour_weights=F32_1D, channel_of_colour=I32_1D, diff_sigma=ti.f32,
                                 weight_floor=ti.f32, dust_remove=ti.i32, output_gain=ti.f32, window2=RUNS_2D)


@ti.func
def inverse_column(sine: ti.template(), k: ti.template()):
    """Column k of the inverse operator (cosine 0, sine 1) as a constant vector over the 16 pixels."""
    return ti.Vector([ti.static(INVERSE[sine][c][k]) for c in ti.static(range(SIDE))])


@ti.func
def compress_row(v, scale_shot: ti.f32, min_shot: ti.f32, linear: ti.f32):
    """Shot-noise compression of a row's 16 values as lanes: scale sqrt(v) above min_shot, the tangent line
    ``linear`` v below (the root is taken of every lane and kept where v > min_shot)."""
    return ti.select(v > min_shot, scale_shot * ti.sqrt(ti.max(v, min_shot)), linear * v)


@ti.func
def demosaic_row(above, mid, below, centre: ti.f32, corner: ti.f32):
    """Filtered interior row of M / W2 (16,): centre x mid + 1/8 x the 4 edge neighbours + corner x the 4
    diagonal ones (R, B: 1/4, 1/16; G: 1/2, 0); columns 0 and 15 stay unfiltered. Rows as vectors: the left and
    right neighbours are the rows shifted by one lane."""
    vertical = above + below
    edge = vertical + shift(mid, 1) + shift(mid, -1)
    diagonal = shift(vertical, 1) + shift(vertical, -1)
    out = centre * mid + 0.125 * edge + corner * diagonal
    return ti.Vector([out[c] if ti.static(0 < c < SIDE - 1) else mid[c] for c in ti.static(range(SIDE))])


@ti.func
def shift(row, by: ti.template()):
    """row[c + by] at lane c (lanes past either end repeat the edge; the filter leaves them unused)."""
    return ti.Vector([row[ti.static(min(max(c + by, 0), SIDE - 1))] for c in ti.static(range(SIDE))])


@ti.kernel
def texture_imclt(clt: ROW8, finite: U8_1D, cams: ti.template(), colours: ti.template(), inputs: TextureInputs,
                  pix: ROW16, cmp: ROW16):
    """One thread per (tile, camera, colour) of finite tiles, the low-passes and inverse operators from ``inputs``
    (``TextureInputs``); pix out: T = sum_q G_{q>>1} (L X_q) G_{q&1}^T (16, 16); cmp out: M / W2 =
    compress(filter3x3(T / W2)) on the 14x14 interior (R, B: [1 2 1; 2 4 2; 1 2 1] / 16; G: [0 1 0; 1 4 1;
    0 1 0] / 8), border unfiltered; mono: T / W2."""
    linear = inputs.scale_shot / ti.sqrt(inputs.min_shot)
    for tile, cam, colour in ti.ndrange(finite.shape[0], cams, colours):
        if finite[tile] != 0:
            base = ((tile * cams + cam) * colours + colour) * 4
            # Column side first: U_q = (L X_q) G_{q&1}^T, (8, 16) each; then T = G_c (U_0 + U_1) + G_s (U_2 + U_3).
            # Rows as vectors: row ky of U is a sum of the operators' constant columns times the CLT row's values.
            u_cos = [ti.Vector.zero(ti.f32, SIDE) for _ in ti.static(range(N))]  # vertical cosine rows: U_0 + U_1
            u_sin = [ti.Vector.zero(ti.f32, SIDE) for _ in ti.static(range(N))]  # vertical sine rows: U_2 + U_3
            for ky in ti.static(range(N)):
                low = inputs.lpf[colour, ky]
                r0 = clt[base + 0, ky] * low
                r1 = clt[base + 1, ky] * low
                r2 = clt[base + 2, ky] * low
                r3 = clt[base + 3, ky] * low
                for kx in ti.static(range(N)):
                    gc = inverse_column(0, kx)
                    gs = inverse_column(1, kx)
                    u_cos[ky] += r0[kx] * gc + r1[kx] * gs
                    u_sin[ky] += r2[kx] * gc + r3[kx] * gs
            out = (tile * cams + cam) * colours + colour
            # The 3x3 filter of row r - 1 runs once row r exists: three rows of T / W2 live at a time.
            centre, corner = 0.25, 0.0625  # R, B
            if colour == 2:  # G (colours R, B, G)
                centre, corner = 0.5, 0.0
            above = ti.Vector.zero(ti.f32, SIDE)
            mid = ti.Vector.zero(ti.f32, SIDE)
            for r in range(SIDE):
                row = ti.Vector.zero(ti.f32, SIDE)
                for ky in ti.static(range(N)):
                    row += inputs.inv_cos[r, ky] * u_cos[ky] + inputs.inv_sin[r, ky] * u_sin[ky]
                pix[out, r] = row
                below = row * inputs.inv_window2[r]
                if ti.static(colours == 1):
                    cmp[out, r] = below
                elif r == 0:  # border row: unfiltered
                    cmp[out, 0] = compress_row(below, inputs.scale_shot, inputs.min_shot, linear)
                elif r > 1:
                    done = demosaic_row(above, mid, below, centre, corner)
                    cmp[out, r - 1] = compress_row(done, inputs.scale_shot, inputs.min_shot, linear)
                above = mid
                mid = below
            if ti.static(colours != 1):
                cmp[out, SIDE - 1] = compress_row(mid, inputs.scale_shot, inputs.min_shot, linear)


# exp_f32: e^x = 2^n e^r, n = round(x / ln 2), r = x - n ln 2, e^r by a degree-7 polynomial on |r| <= ln 2 / 2
# (Cephes' single-precision coefficients). The reduction is written in two parts (Cody-Waite: LN2_HIGH has few
# bits, so n LN2_HIGH is exact), but Taichi's fast math may merge them into n times ln 2 rounded to float32:
# measured against float64 exp, relative error 1.2e-7 (~1 ulp) at n = 0 plus ~3.5e-8 per unit of |n| (5.6e-7 at
# x = -10, 4e-6 at -72; the weights add 1e-4 to e^x, far above such errors once e^x is small). 0 below ln of
# the smallest normal float (-87.33; libm returns subnormals there).
LN2_HIGH, LN2_LOW = 0.693359375, -2.12194440e-4
EXP_POLY = (1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3, 4.1665795894e-2, 1.6666665459e-1, 5.0000001201e-1)
EXP_MIN = -87.33  # just above ln(2^-126)


@ti.func
def exp_f32(x: ti.f32) -> ti.f32:
    """e^x in float32 as straight-line code (see EXP_POLY); 0 for x < EXP_MIN."""
    y = ti.min(ti.max(x, EXP_MIN), 88.0)
    t = y * 1.4426950408889634  # x / ln 2
    n = ti.cast(t + ti.select(t < 0.0, -0.5, 0.5), ti.i32)  # round half away from zero
    r = y - ti.cast(n, ti.f32) * LN2_HIGH
    r = r - ti.cast(n, ti.f32) * LN2_LOW
    p = r * EXP_POLY[0] + EXP_POLY[1]
    for c in ti.static(EXP_POLY[2:]):
        p = p * r + c
    e = (p * r * r + r + 1.0) * ti.bit_cast((n + 127) << 23, ti.f32)  # times 2^n
    return ti.select(x < EXP_MIN, 0.0, e)


@ti.func
def lanes_exp(x):
    out = ti.Vector.zero(ti.f32, LANES)
    for i in ti.static(range(LANES)):
        out[i] = exp_f32(x[i])
    return out


@ti.func
def fade_ramp(i: ti.i32) -> ti.f32:
    return 0.5 * (1.0 - ti.cos(ti.math.pi * (ti.cast(i, ti.f32) + 0.5) / 16.0))


@ti.func
def alpha_fade(north: ti.i32, east: ti.i32, south: ti.i32, west: ti.i32, r: ti.i32, c0: ti.i32):
    """§7.4 for pixels (r, c0 .. c0 + LANES - 1): one contributing neighbour -> ramp towards it; two adjacent -> max
    of both; else 1."""
    count = north + east + south + west
    out = ti.Vector([1.0] * LANES)
    if count == 1 or (count == 2 and north != south):
        vertical = fade_ramp(r)
        if north:
            vertical = fade_ramp(15 - r)
        horizontal = ti.Vector([fade_ramp(15 - c0 - i) for i in ti.static(range(LANES))])
        if east:
            horizontal = ti.Vector([fade_ramp(c0 + i) for i in ti.static(range(LANES))])
        if count == 2:
            out = ti.max(vertical, horizontal)
        elif north or south:
            out = ti.Vector([vertical] * LANES)
        else:
            out = horizontal
    return out


@ti.func
def neighbour(finite: ti.template(), tile: ti.i32, inside: ti.i32) -> ti.i32:
    """Whether the neighbour ``tile`` contributes; positions outside the frame (``inside`` 0) count as contributing,
    so only the region's edges inside the frame fade. Read only inside (never off the tile grid)."""
    out = 1
    if inside:
        out = ti.cast(finite[tile] != 0, ti.i32)
    return out


@ti.kernel
def texture_combine(pix: RUNS, cmp: RUNS, finite: U8_1D, first: ti.i32, cams: ti.template(), colours: ti.template(),
                    inputs: TextureInputs, rgba: RUNS):
    """One thread per run (tile, r, run) of LANES pixels of one band's contributing tiles (``pix``, ``cmp``: the
    band's tiles, frame tiles ``first`` on, as (n, 16, 16 / LANES) runs of LANES; ``finite``: the whole frame's),
    per pixel: weights (§7.3 a-d), colour = weighted mean of T, alpha = W2 x mean weight, times the alpha fade,
    into the tile's contribution (colours x output_gain) in the ring ``rgba`` (texture.texture_combine's: tile
    row ty in slot row ty % ring_rows); the grid and settings from ``inputs`` (``TextureInputs``)."""
    xi = 1.0 / (2.0 * inputs.diff_sigma * inputs.diff_sigma)
    # Per rig constants, once: -xi / |offset_b - offset_a|^2 of each pair (a < b) and the colour weights.
    pair_scale = ti.Vector.zero(ti.f32, cams * cams)
    for a in ti.static(range(cams)):
        for b in ti.static(range(a + 1, cams)):
            ox = inputs.offsets[b, 0] - inputs.offsets[a, 0]
            oy = inputs.offsets[b, 1] - inputs.offsets[a, 1]
            pair_scale[a * cams + b] = -xi / (ox * ox + oy * oy)
    cw = ti.Vector([inputs.colour_weights[k] for k in ti.static(range(colours))])
    for band_tile, r, run in ti.ndrange(pix.shape[0] // (cams * colours), SIDE, SIDE // LANES):
        tile = first + band_tile
        if finite[tile] != 0:
            base = band_tile * cams
            ty = tile // inputs.tiles_x
            tx = tile - ty * inputs.tiles_x
            out = ((ty % inputs.ring_rows) * inputs.tiles_x + tx) * (colours + 1)
            # compared values M / W2 of the run, [camera][colour]
            m = [[cmp[(base + cam) * colours + k, r, run] for k in ti.static(range(colours))]
                 for cam in ti.static(range(cams))]
            # a. pairwise agreement
            w = [ti.Vector.zero(ti.f32, LANES) for _ in ti.static(range(cams))]
            for a in ti.static(range(cams)):
                for b in ti.static(range(a + 1, cams)):
                    d = ti.Vector.zero(ti.f32, LANES)
                    for k in ti.static(range(colours)):
                        diff = m[a][k] - m[b][k]
                        d += cw[k] * diff * diff
                    v = lanes_exp(d * pair_scale[a * cams + b]) + inputs.weight_floor
                    w[a] += v
                    w[b] += v
            # b. the two best cameras (first index wins ties) and their weighted mean
            best = ti.Vector.zero(ti.i32, LANES)
            wb = w[0]
            mb = [m[0][k] for k in ti.static(range(colours))]
            for cam in ti.static(range(1, cams)):
                more = w[cam] > wb
                best = ti.select(more, cam, best)
                wb = ti.select(more, w[cam], wb)
                for k in ti.static(range(colours)):
                    mb[k] = ti.select(more, m[cam][k], mb[k])
            ws = ti.Vector([-1.0] * LANES)  # weights are > 0: the first camera other than the best replaces it
            ms = [ti.Vector.zero(ti.f32, LANES) for _ in ti.static(range(colours))]
            for cam in ti.static(range(cams)):
                take = (best != cam) & (w[cam] > ws)
                ws = ti.select(take, w[cam], ws)
                for k in ti.static(range(colours)):
                    ms[k] = ti.select(take, m[cam][k], ms[k])
            scale = 1.0 / (wb + ws)
            mean = [(wb * mb[k] + ws * ms[k]) * scale for k in ti.static(range(colours))]
            # c. agreement of every camera with the two best cameras' mean
            total = ti.Vector.zero(ti.f32, LANES)
            for cam in ti.static(range(cams)):
                d = ti.Vector.zero(ti.f32, LANES)
                for k in ti.static(range(colours)):
                    diff = m[cam][k] - mean[k]
                    d += cw[k] * diff * diff
                w[cam] = lanes_exp(-xi * d) + inputs.weight_floor
                total += w[cam]
            # d. dust removal
            if inputs.dust_remove:
                worst = ti.Vector.zero(ti.i32, LANES)
                w_worst = w[0]
                for cam in ti.static(range(1, cams)):
                    less = w[cam] < w_worst
                    worst = ti.select(less, cam, worst)
                    w_worst = ti.select(less, w[cam], w_worst)
                others = ti.cast(cams - 1, ti.f32)
                mu = (total - w_worst) / others
                boost = 1.0 + w_worst * (mu - w_worst) / (others * mu * mu)
                total = ti.Vector.zero(ti.f32, LANES)
                for cam in ti.static(range(cams)):
                    w[cam] = ti.select(worst == cam, w_worst * w_worst / mu, w[cam] * boost)
                    total += w[cam]
            # e. colour and alpha, faded at the edge of the contributing region
            north = neighbour(finite, tile - inputs.tiles_x, ty > 0)
            south = neighbour(finite, tile + inputs.tiles_x, ty + 1 < inputs.tiles_y)
            west = neighbour(finite, tile - 1, tx > 0)
            east = neighbour(finite, tile + 1, tx + 1 < inputs.tiles_x)
            fade = alpha_fade(north, east, south, west, r, run * LANES)
            gain = inputs.output_gain * fade / total
            for k in ti.static(range(colours)):
                acc = ti.Vector.zero(ti.f32, LANES)
                for cam in ti.static(range(cams)):
                    acc += w[cam] * pix[(base + cam) * colours + k, r, run]
                rgba[out + inputs.channel_of_colour[k], r, run] = gain * acc
            rgba[out + colours, r, run] = fade * inputs.window2[r, run] * total / ti.cast(cams, ti.f32)


@ti.kernel
def overlap_add(rgba: F32_3D, finite: U8_1D, inputs: TextureInputs, y0: ti.i32, rows: ti.i32, canvas: F32_3D):
    """canvas[ch, y, x] for canvas rows y0 .. y0 + rows - 1 = sum of the contributing tiles' ``rgba`` (the ring of
    texture_combine) covering (y, x), tiles in row-major order (the Warp kernel's order: bit-reproducible with
    any thread count); every pixel of those rows is written. One thread per 8 pixels of a canvas row: the same up
    to 4 tiles cover them (canvas width W + 8, a multiple of 8)."""
    for ch, row, block in ti.ndrange(canvas.shape[0], rows, canvas.shape[2] // 8):
        y = y0 + row
        channels = canvas.shape[0]
        acc = ti.Vector.zero(ti.f32, 8)
        for dy, dx in ti.static(ti.ndrange(2, 2)):
            ty = y // 8 - 1 + dy
            tx = block - 1 + dx
            if ty >= 0 and ty < inputs.tiles_y and tx >= 0 and tx < inputs.tiles_x:
                tile = ty * inputs.tiles_x + tx
                if finite[tile] != 0:
                    slot = (ty % inputs.ring_rows) * inputs.tiles_x + tx
                    for i in ti.static(range(8)):
                        acc[i] += rgba[slot * channels + ch, y - 8 * ty, i + 8 * (1 - dx)]
        for i in ti.static(range(8)):
            canvas[ch, y, 8 * block + i] = acc[i]
