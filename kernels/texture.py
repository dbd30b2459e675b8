"""Texture: shift-corrected CLT tiles -> RGBA image with alpha from the cameras' agreement (tile_processor.md
§7.3, §7.4).

Four launches: ``texture_imclt`` (one block per tile: low-pass and inverse MCLT of every camera and colour as
two matrix products per quadrant), ``texture_demosaic`` (per pixel: 3x3 filter of the zero-filled colours and
shot-noise compression), ``texture_combine`` (per pixel of one band's tiles: camera weights, colour, alpha and
the alpha fade at the edge of the processed region, into the tile's slot of the RGBA contributions),
``overlap_add`` (per canvas pixel: the sum of the up to 4 tiles that cover it, in a fixed order - no float
atomics, so the texture is bit-reproducible on every device and thread count).

Layouts: ``clt`` (tiles * cams * colours * 4, 8, 8); ``pix``/``cmp`` (tiles * cams * colours, 16, 16) = the
IMCLT tiles T and the compared values M / W2 (kept unwindowed: dividing a windowed value by the tiny corner
window again would cost float32 precision); ``weights`` (band tiles * cams, 16, 16); ``rgba`` (tiles *
channels, 16, 16) per-tile contributions in output channel order; ``canvas`` (channels, H + 8, W + 8), image
pixel u at canvas u + 4.
"""

import warp as wp

from tpnet_gpu.runtime.warp_setup import kernel_module_options

wp.set_module_options(kernel_module_options())  # hashed with every kernel source (warp_setup)


@wp.struct
class TextureInputs:
    """What the texture kernels read besides one band's arrays: one processor's rig, tile grid, texture settings
    and tables, built once with its texture buffers.

    Fields:
        cams, colours: cameras and colours (3 R, B, G; 1 mono).
        tiles_x, tiles_y: the frame's tile grid.
        ring_rows: tile rows of the ``rgba`` ring.
        lpf: (colours, 8, 8) each colour's low-pass before the inverse MCLT.
        inv_cos, inv_sin: (16, 8) per-axis inverse operators (window/2 x unfold x DTT-IV); inv_cos_t, inv_sin_t:
            (8, 16) their transposes.
        inv_window2: (16, 16) 1 / W2, W2 = w(r)^2 w(c)^2.
        scale_shot, min_shot: the shot-noise compression (``compress``).
        offsets: (cams,) the cameras' offsets r_i in baselines.
        colour_weights: (colours,) the colours' weights in the cameras' agreement.
        channel_of_colour: (colours,) int32 each colour's output channel (R, G, B order).
        diff_sigma, weight_floor: the agreement's scale and the floor added to each weight (§7.3).
        dust_remove: down-weight the worst camera (§7.3 d).
        output_gain: the colours' gain.
    """

    cams: int
    colours: int
    tiles_x: int
    tiles_y: int
    ring_rows: int
    lpf: wp.array3d(dtype=wp.float32)
    inv_cos: wp.array2d(dtype=wp.float32)
    inv_sin: wp.array2d(dtype=wp.float32)
    inv_cos_t: wp.array2d(dtype=wp.float32)
    inv_sin_t: wp.array2d(dtype=wp.float32)
    inv_window2: wp.array2d(dtype=wp.float32)
    scale_shot: float
    min_shot: float
    offsets: wp.array(dtype=wp.vec2f)
    colour_weights: wp.array(dtype=wp.float32)
    channel_of_colour: wp.array(dtype=wp.int32)
    diff_sigma: float
    weight_floor: float
    dust_remove: bool
    output_gain: float


@wp.kernel
def texture_imclt(
    clt: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    inputs: TextureInputs,
    pix: wp.array3d(dtype=wp.float32),
):
    """One block per tile, the inverse operators and low-passes from ``inputs`` (``TextureInputs``); pix out:
    T = sum_q G_{q>>1} (L X_q) G_{q&1}^T."""
    tile = wp.tid()
    if not finite[tile]:
        return
    cams = inputs.cams
    colours = inputs.colours
    inv_cos = inputs.inv_cos  # a struct's array is loaded as a tile from a local (Warp 1.19: not from the field)
    inv_sin = inputs.inv_sin
    inv_cos_t = inputs.inv_cos_t
    inv_sin_t = inputs.inv_sin_t
    g_c = wp.tile_load(inv_cos, shape=(16, 8))
    g_s = wp.tile_load(inv_sin, shape=(16, 8))
    gt_c = wp.tile_load(inv_cos_t, shape=(8, 16))
    gt_s = wp.tile_load(inv_sin_t, shape=(8, 16))
    for cam in range(cams):
        for colour in range(colours):
            low = wp.tile_load(inputs.lpf[colour], shape=(8, 8))
            base = ((tile * cams + cam) * colours + colour) * 4
            x0 = wp.tile_map(wp.mul, wp.tile_load(clt[base + 0], shape=(8, 8)), low)
            x1 = wp.tile_map(wp.mul, wp.tile_load(clt[base + 1], shape=(8, 8)), low)
            x2 = wp.tile_map(wp.mul, wp.tile_load(clt[base + 2], shape=(8, 8)), low)
            x3 = wp.tile_map(wp.mul, wp.tile_load(clt[base + 3], shape=(8, 8)), low)
            out = wp.tile_zeros(shape=(16, 16), dtype=wp.float32)
            wp.tile_matmul(g_c, wp.tile_matmul(x0, gt_c), out)  # CC: vertical cos, horizontal cos
            wp.tile_matmul(g_c, wp.tile_matmul(x1, gt_s), out)  # SC
            wp.tile_matmul(g_s, wp.tile_matmul(x2, gt_c), out)  # CS
            wp.tile_matmul(g_s, wp.tile_matmul(x3, gt_s), out)  # SS
            wp.tile_store(pix[(tile * cams + cam) * colours + colour], out)


@wp.func
def window_sq(r: int, c: int) -> float:
    """w(r)^2 w(c)^2 with w(n) = sin(pi (2n + 1) / 32)."""
    wr = wp.sin(wp.pi * (2.0 * float(r) + 1.0) / 32.0)
    wc = wp.sin(wp.pi * (2.0 * float(c) + 1.0) / 32.0)
    return wr * wr * wc * wc


@wp.func
def compress(v: float, scale_shot: float, min_shot: float, linear: float) -> float:
    """Shot-noise compression: scale sqrt(v) above min_shot, the tangent line ``linear`` v below."""
    if v > min_shot:
        return scale_shot * wp.sqrt(v)
    return linear * v


@wp.kernel
def texture_demosaic(
    pix: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    inputs: TextureInputs,
    cmp: wp.array3d(dtype=wp.float32),
):
    """Per pixel of every (tile, camera, colour): M / W2 = compress(filter3x3(T / W2)) on the 14x14 interior
    (R, B: [1 2 1; 2 4 2; 1 2 1] / 16; G: [0 1 0; 1 4 1; 0 1 0] / 8, as centre x T + 1/8 x the 4 edge
    neighbours + corner x the 4 diagonal ones), border unfiltered; mono: T / W2."""
    i, r, c = wp.tid()
    colours = inputs.colours
    inv_window2 = inputs.inv_window2
    if not finite[i // (inputs.cams * colours)]:
        return
    v = pix[i, r, c] * inv_window2[r, c]
    if colours == 1:
        cmp[i, r, c] = v
        return
    if r > 0 and r < 15 and c > 0 and c < 15:
        centre = 0.25  # R, B
        corner = 0.0625
        if (i % colours) == 2:  # G (colours R, B, G)
            centre = 0.5
            corner = 0.0
        edge = (pix[i, r - 1, c] * inv_window2[r - 1, c] + pix[i, r + 1, c] * inv_window2[r + 1, c]
                + pix[i, r, c - 1] * inv_window2[r, c - 1] + pix[i, r, c + 1] * inv_window2[r, c + 1])
        diagonal = (pix[i, r - 1, c - 1] * inv_window2[r - 1, c - 1] + pix[i, r - 1, c + 1] * inv_window2[r - 1, c + 1]
                    + pix[i, r + 1, c - 1] * inv_window2[r + 1, c - 1]
                    + pix[i, r + 1, c + 1] * inv_window2[r + 1, c + 1])
        v = centre * v + 0.125 * edge + corner * diagonal
    scale_shot = inputs.scale_shot
    cmp[i, r, c] = compress(v, scale_shot, inputs.min_shot, scale_shot / wp.sqrt(inputs.min_shot))


@wp.func
def fade_ramp(i: int) -> float:
    return 0.5 * (1.0 - wp.cos(wp.pi * (float(i) + 0.5) / 16.0))


@wp.func
def alpha_fade(north: bool, east: bool, south: bool, west: bool, r: int, c: int) -> float:
    """§7.4: one contributing neighbour -> ramp towards it; two adjacent -> max of both; else 1."""
    count = int(north) + int(east) + int(south) + int(west)
    if count == 1:
        if north:
            return fade_ramp(15 - r)
        if east:
            return fade_ramp(c)
        if south:
            return fade_ramp(r)
        return fade_ramp(15 - c)
    if count == 2 and north != south:
        vertical = fade_ramp(r)
        if north:
            vertical = fade_ramp(15 - r)
        horizontal = fade_ramp(15 - c)
        if east:
            horizontal = fade_ramp(c)
        return wp.max(vertical, horizontal)
    return 1.0


@wp.kernel
def texture_combine(
    pix: wp.array3d(dtype=wp.float32),
    cmp: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    first: int,
    inputs: TextureInputs,
    weights: wp.array3d(dtype=wp.float32),
    rgba: wp.array3d(dtype=wp.float32),
):
    """Per pixel (tile, r, c) of one band's contributing tiles (``pix``, ``cmp``, ``weights``: the band's tiles,
    frame tiles ``first`` on; ``finite``: the whole frame's): weights (§7.3 a-d), colour = weighted mean of T,
    alpha = W2 x mean weight, times the alpha fade, into the tile's contribution (colours x output_gain) in the
    ring ``rgba`` (ring_rows * tiles_x * (colours + 1), 16, 16): tile row ty in slot row ty % ring_rows; the rig,
    grid and settings from ``inputs`` (``TextureInputs``)."""
    band_tile, r, c = wp.tid()
    cams = inputs.cams
    colours = inputs.colours
    tiles_x = inputs.tiles_x
    colour_weights = inputs.colour_weights
    weight_floor = inputs.weight_floor
    tile = first + band_tile
    if not finite[tile]:
        return
    w2 = window_sq(r, c)
    xi = 1.0 / (2.0 * inputs.diff_sigma * inputs.diff_sigma)
    base = band_tile * cams
    # a. pairwise agreement
    for cam in range(cams):
        weights[base + cam, r, c] = 0.0
    for a in range(cams):
        for b in range(a + 1, cams):
            d = float(0.0)
            for k in range(colours):
                diff = cmp[(base + a) * colours + k, r, c] - cmp[(base + b) * colours + k, r, c]
                d += colour_weights[k] * diff * diff
            v = wp.exp(d * (-xi / wp.length_sq(inputs.offsets[b] - inputs.offsets[a]))) + weight_floor
            weights[base + a, r, c] = weights[base + a, r, c] + v
            weights[base + b, r, c] = weights[base + b, r, c] + v
    # b. the two best cameras (first index wins ties)
    best = int(0)
    for cam in range(1, cams):
        if weights[base + cam, r, c] > weights[base + best, r, c]:
            best = cam
    second = int(-1)
    for cam in range(cams):
        if cam != best:
            if second < 0:
                second = cam
            elif weights[base + cam, r, c] > weights[base + second, r, c]:
                second = cam
    wb = weights[base + best, r, c]
    ws = weights[base + second, r, c]
    # c. agreement of every camera with the two best cameras' mean
    total = float(0.0)
    for cam in range(cams):
        d = float(0.0)
        for k in range(colours):
            mean = (wb * cmp[(base + best) * colours + k, r, c] + ws * cmp[(base + second) * colours + k, r, c]) * (
                1.0 / (wb + ws))
            diff = cmp[(base + cam) * colours + k, r, c] - mean
            d += colour_weights[k] * diff * diff
        weights[base + cam, r, c] = wp.exp(-xi * d) + weight_floor
        total += weights[base + cam, r, c]
    # d. dust removal
    if inputs.dust_remove:
        worst = int(0)
        for cam in range(1, cams):
            if weights[base + cam, r, c] < weights[base + worst, r, c]:
                worst = cam
        w_worst = weights[base + worst, r, c]
        others = float(cams - 1)
        mu = (total - w_worst) / others
        total = float(0.0)
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
    north = ty == 0 or finite[tile - tiles_x]
    south = ty + 1 == inputs.tiles_y or finite[tile + tiles_x]
    west = tx == 0 or finite[tile - 1]
    east = tx + 1 == tiles_x or finite[tile + 1]
    fade = alpha_fade(north, east, south, west, r, c)
    out = ((ty % inputs.ring_rows) * tiles_x + tx) * (colours + 1)
    gain = inputs.output_gain * fade / total
    for k in range(colours):
        acc = float(0.0)
        for cam in range(cams):
            acc += weights[base + cam, r, c] * pix[(base + cam) * colours + k, r, c]
        rgba[out + inputs.channel_of_colour[k], r, c] = gain * acc
    rgba[out + colours, r, c] = fade * w2 * total / float(cams)


@wp.kernel
def overlap_add(
    rgba: wp.array3d(dtype=wp.float32),
    finite: wp.array(dtype=wp.bool),
    inputs: TextureInputs,
    y0: int,
    canvas: wp.array3d(dtype=wp.float32),
):
    """canvas[ch, y, x] for the canvas rows y = y0 + row of the launch (channels, rows, W + 8) = sum of the
    contributing tiles' ``rgba`` (the ring of texture_combine) that cover (y, x), tiles in row-major order
    (canvas pixel y is row y - 8 ty of tiles ty = y // 8 - 1 and y // 8); every pixel of those rows is written."""
    ch, row, x = wp.tid()
    tiles_x = inputs.tiles_x
    tiles_y = inputs.tiles_y
    y = y0 + row
    channels = canvas.shape[0]
    acc = float(0.0)
    for ty in range(y // 8 - 1, y // 8 + 1):
        for tx in range(x // 8 - 1, x // 8 + 1):
            if ty >= 0 and ty < tiles_y and tx >= 0 and tx < tiles_x:
                tile = ty * tiles_x + tx
                if finite[tile]:
                    slot = (ty % inputs.ring_rows) * tiles_x + tx
                    acc += rgba[slot * channels + ch, y - 8 * ty, x - 8 * tx]
    canvas[ch, y, x] = acc
