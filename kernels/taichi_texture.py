"""Taichi twin of kernels/texture.py: shift-corrected CLT tiles -> RGBA image with alpha from the cameras'
agreement (tile_processor.md §7.3, §7.4), spread over every core.

The same launches, arguments, tables and layouts as the Warp module (see there): ``texture_imclt`` (one thread
per tile, camera and colour: low-pass and inverse MCLT as two matrix products per quadrant), ``texture_demosaic``
(per pixel), ``texture_combine`` (per pixel: camera weights, colour, alpha and the alpha fade, into the
tile's RGBA contribution), ``overlap_add`` (per canvas pixel, fixed order, no atomics). Bool masks are uint8
views; ``offsets`` is (cams, 2).
"""

import taichi as ti

from tpnet_gpu.kernels.taichi_types import F32_1D, F32_2D, F32_3D, I32_1D, U8_1D
from tpnet_gpu.tables import DTT_SIZE as N  # frequencies per axis
from tpnet_gpu.tables import TILE_SIZE as SIDE  # window side, pixels


@ti.kernel
def texture_imclt(
    clt: F32_3D,
    finite: U8_1D,
    cams: ti.i32,
    colours: ti.i32,
    lpf: F32_3D,
    inv_cos: F32_2D,
    inv_sin: F32_2D,
    pix: F32_3D,
):
    """One thread per (tile, camera, colour) of finite tiles. lpf: (colours, 8, 8); inv_*: (16, 8) per-axis
    inverse operators; pix out: T = sum_q G_{q>>1} (L X_q) G_{q&1}^T (16, 16)."""
    for tile, cam, colour in ti.ndrange(finite.shape[0], cams, colours):
        if finite[tile] != 0:
            base = ((tile * cams + cam) * colours + colour) * 4
            # Column side first: U_q = (L X_q) G_{q&1}^T, (8, 16) each; then T = G_c (U_0 + U_1) + G_s (U_2 + U_3).
            u_cos = ti.Matrix.zero(ti.f32, N, SIDE)  # vertical cosine rows: U_0 + U_1
            u_sin = ti.Matrix.zero(ti.f32, N, SIDE)  # vertical sine rows: U_2 + U_3
            for ky in range(N):
                for kx in ti.static(range(N)):
                    low = lpf[colour, ky, kx]
                    x0 = clt[base + 0, ky, kx] * low
                    x1 = clt[base + 1, ky, kx] * low
                    x2 = clt[base + 2, ky, kx] * low
                    x3 = clt[base + 3, ky, kx] * low
                    for c in ti.static(range(SIDE)):
                        gc = inv_cos[c, kx]
                        gs = inv_sin[c, kx]
                        u_cos[ky, c] += x0 * gc + x1 * gs
                        u_sin[ky, c] += x2 * gc + x3 * gs
            out = (tile * cams + cam) * colours + colour
            for r in range(SIDE):
                row = ti.Vector.zero(ti.f32, SIDE)
                for ky in ti.static(range(N)):
                    gc = inv_cos[r, ky]
                    gs = inv_sin[r, ky]
                    for c in ti.static(range(SIDE)):
                        row[c] += gc * u_cos[ky, c] + gs * u_sin[ky, c]
                for c in ti.static(range(SIDE)):
                    pix[out, r, c] = row[c]


@ti.kernel
def texture_demosaic(
    pix: F32_3D,
    finite: U8_1D,
    cams: ti.i32,
    colours: ti.i32,
    scale_shot: ti.f32,
    min_shot: ti.f32,
    window2: F32_2D,
    cmp: F32_3D,
):
    """Per pixel of every (tile, camera, colour): M / W2 = compress(filter3x3(T / W2)) on the 14x14 interior
    (R, B: [1 2 1; 2 4 2; 1 2 1] / 16; G: [0 1 0; 1 4 1; 0 1 0] / 8), border unfiltered; mono: T / W2.
    window2: (16, 16) W2 = w(r)^2 w(c)^2 (the Warp kernel evaluates it in place)."""
    for i, r, c in pix:
        if finite[i // (cams * colours)] != 0:
            v = pix[i, r, c] / window2[r, c]
            if colours == 1:
                cmp[i, r, c] = v
            else:
                if r > 0 and r < SIDE - 1 and c > 0 and c < SIDE - 1:
                    acc = 0.0
                    green = (i % colours) == 2
                    for dy, dx in ti.static(ti.ndrange((-1, 2), (-1, 2))):
                        u = pix[i, r + dy, c + dx] / window2[r + dy, c + dx]
                        if green:
                            wgt = 0.5 if dy == 0 and dx == 0 else (0.125 if dy == 0 or dx == 0 else 0.0)
                            acc += wgt * u
                        else:
                            acc += (2 - abs(dy)) * (2 - abs(dx)) / 16.0 * u
                    v = acc
                if v > min_shot:
                    v = scale_shot * ti.sqrt(v)
                else:
                    v = scale_shot * v / ti.sqrt(min_shot)
                cmp[i, r, c] = v


@ti.func
def fade_ramp(i: ti.i32) -> ti.f32:
    return 0.5 * (1.0 - ti.cos(ti.math.pi * (ti.cast(i, ti.f32) + 0.5) / 16.0))


@ti.func
def alpha_fade(north: ti.i32, east: ti.i32, south: ti.i32, west: ti.i32, r: ti.i32, c: ti.i32) -> ti.f32:
    """§7.4: one contributing neighbour -> ramp towards it; two adjacent -> max of both; else 1."""
    count = north + east + south + west
    out = 1.0
    if count == 1:
        if north:
            out = fade_ramp(15 - r)
        elif east:
            out = fade_ramp(c)
        elif south:
            out = fade_ramp(r)
        else:
            out = fade_ramp(15 - c)
    elif count == 2 and north != south:
        vertical = fade_ramp(r)
        if north:
            vertical = fade_ramp(15 - r)
        horizontal = fade_ramp(15 - c)
        if east:
            horizontal = fade_ramp(c)
        out = ti.max(vertical, horizontal)
    return out


@ti.kernel
def texture_combine(
    pix: F32_3D,
    cmp: F32_3D,
    finite: U8_1D,
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    cams: ti.i32,
    colours: ti.i32,
    offsets: F32_2D,
    colour_weights: F32_1D,
    channel_of_colour: I32_1D,
    diff_sigma: ti.f32,
    weight_floor: ti.f32,
    dust_remove: ti.i32,
    output_gain: ti.f32,
    window2: F32_2D,
    weights: F32_3D,
    rgba: F32_3D,
):
    """Per pixel (tile, r, c) of contributing tiles: weights (§7.3 a-d), colour = weighted mean of T, alpha =
    W2 x mean weight, times the alpha fade, into the tile's contribution ``rgba`` (colours x output_gain).
    window2 as in texture_demosaic."""
    for tile, r, c in ti.ndrange(finite.shape[0], SIDE, SIDE):
        if finite[tile] != 0:
            w2 = window2[r, c]
            xi = 1.0 / (2.0 * diff_sigma * diff_sigma)
            base = tile * cams
            # a. pairwise agreement
            for cam in range(cams):
                weights[base + cam, r, c] = 0.0
            for a in range(cams):
                for b in range(a + 1, cams):
                    d = 0.0
                    for k in range(colours):
                        diff = cmp[(base + a) * colours + k, r, c] - cmp[(base + b) * colours + k, r, c]
                        d += colour_weights[k] * diff * diff
                    ox = offsets[b, 0] - offsets[a, 0]
                    oy = offsets[b, 1] - offsets[a, 1]
                    v = ti.exp(-xi * d / (ox * ox + oy * oy)) + weight_floor
                    weights[base + a, r, c] = weights[base + a, r, c] + v
                    weights[base + b, r, c] = weights[base + b, r, c] + v
            # b. the two best cameras (first index wins ties)
            best = 0
            for cam in range(1, cams):
                if weights[base + cam, r, c] > weights[base + best, r, c]:
                    best = cam
            second = -1
            for cam in range(cams):
                if cam != best:
                    if second < 0:
                        second = cam
                    elif weights[base + cam, r, c] > weights[base + second, r, c]:
                        second = cam
            wb = weights[base + best, r, c]
            ws = weights[base + second, r, c]
            # c. agreement of every camera with the two best cameras' mean
            total = 0.0
            for cam in range(cams):
                d = 0.0
                for k in range(colours):
                    mean = (wb * cmp[(base + best) * colours + k, r, c]
                            + ws * cmp[(base + second) * colours + k, r, c]) / (wb + ws)
                    diff = cmp[(base + cam) * colours + k, r, c] - mean
                    d += colour_weights[k] * diff * diff
                weights[base + cam, r, c] = ti.exp(-xi * d) + weight_floor
                total += weights[base + cam, r, c]
            # d. dust removal
            if dust_remove:
                worst = 0
                for cam in range(1, cams):
                    if weights[base + cam, r, c] < weights[base + worst, r, c]:
                        worst = cam
                w_worst = weights[base + worst, r, c]
                others = ti.cast(cams - 1, ti.f32)
                mu = (total - w_worst) / others
                total = 0.0
                for cam in range(cams):
                    w = weights[base + cam, r, c]
                    if cam == worst:
                        w = w_worst * w_worst / mu
                    else:
                        w = w * (1.0 + w_worst * (mu - w_worst) / (others * mu * mu))
                    weights[base + cam, r, c] = w
                    total += w
            # e. colour and alpha, faded at the edge of the contributing region, overlap-added
            ty = tile // tiles_x
            tx = tile - ty * tiles_x
            # Positions outside the frame count as contributing: only the region's edges inside the frame fade.
            # Neighbour reads guarded by if statements (never read off the tile grid).
            north = 1
            if ty > 0:
                north = ti.cast(finite[tile - tiles_x] != 0, ti.i32)
            south = 1
            if ty + 1 < tiles_y:
                south = ti.cast(finite[tile + tiles_x] != 0, ti.i32)
            west = 1
            if tx > 0:
                west = ti.cast(finite[tile - 1] != 0, ti.i32)
            east = 1
            if tx + 1 < tiles_x:
                east = ti.cast(finite[tile + 1] != 0, ti.i32)
            fade = alpha_fade(north, east, south, west, r, c)
            out = tile * (colours + 1)
            for k in range(colours):
                acc = 0.0
                for cam in range(cams):
                    acc += weights[base + cam, r, c] * pix[(base + cam) * colours + k, r, c]
                rgba[out + channel_of_colour[k], r, c] = output_gain * fade * acc / total
            rgba[out + colours, r, c] = fade * w2 * total / ti.cast(cams, ti.f32)


@ti.kernel
def overlap_add(rgba: F32_3D, finite: U8_1D, tiles_x: ti.i32, tiles_y: ti.i32, canvas: F32_3D):
    """canvas[ch, y, x] = sum of the contributing tiles' ``rgba`` covering (y, x), tiles in row-major order (the
    Warp kernel's order: bit-reproducible with any thread count); every canvas pixel is written."""
    for ch, y, x in canvas:
        channels = canvas.shape[0]
        acc = 0.0
        for dy in ti.static(range(2)):
            for dx in ti.static(range(2)):
                ty = y // 8 - 1 + dy
                tx = x // 8 - 1 + dx
                if ty >= 0 and ty < tiles_y and tx >= 0 and tx < tiles_x:
                    tile = ty * tiles_x + tx
                    if finite[tile] != 0:
                        acc += rgba[tile * channels + ch, y - 8 * ty, x - 8 * tx]
        canvas[ch, y, x] = acc
