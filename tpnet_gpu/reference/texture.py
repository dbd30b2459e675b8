"""Golden reference: textures - per-tile RGBA from the cameras' shift-corrected CLT tiles, alpha from their
agreement, and the overlap-add into an image (tile_processor.md §7.3, §7.4). Float64, NumPy.

Colour order R, B, G (mono: one colour). Per tile: T = IMCLT(L_k * F) per camera and colour; a demosaic
(3x3 filter of T / w^2 w^2 on the 14x14 interior) and shot-noise compression give M, the values compared
between cameras; weights from the pairwise differences, the two best cameras' mean, each camera's distance
to it, dust removal; colour = weighted mean of T, alpha = w^2 w^2 x mean weight.
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import operators, tables
from tpnet_gpu.reference.mclt import imclt, overlap_add

RB_FILTER = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]]) / 16.0
G_FILTER = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]]) / 8.0


def demosaic_interior(u, filt) -> np.ndarray:
    """3x3 filter of ``(..., 16, 16)`` on the 14x14 interior; rows and columns 0 and 15 are copied."""
    u = np.asarray(u, dtype=np.float64)
    out = u.copy()
    acc = np.zeros(u.shape[:-2] + (14, 14))
    for dy in range(3):
        for dx in range(3):
            acc += filt[dy, dx] * u[..., dy : dy + 14, dx : dx + 14]
    out[..., 1:15, 1:15] = acc
    return out


def shot_compress(v, scale: float, min_shot: float) -> np.ndarray:
    """v -> scale sqrt(v) where v > min_shot, else scale v / sqrt(min_shot) (continuous at min_shot)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v > min_shot, scale * np.sqrt(np.maximum(v, min_shot)), scale * v / np.sqrt(min_shot))


def texture_tiles(
    clt,
    camera_offsets,
    *,
    lpf_sigmas=None,
    colour_weights=None,
    diff_sigma: float = tables.TEXTURE_DIFF_SIGMA,
    min_shot: float = tables.TEXTURE_MIN_SHOT,
    scale_shot: float = tables.TEXTURE_SCALE_SHOT,
    dust_remove: bool = True,
) -> np.ndarray:
    """RGBA texture tiles ``(T..., colours + 1, 16, 16)`` (colours in R, B, G order, then alpha), still windowed.

    clt: ``(T..., cams, colours, 4, 8, 8)`` shift-corrected CLT tiles; camera_offsets: ``(cams, 2)`` r_i (pair
    differences are normalised by |r_b - r_a|^2). ``None`` picks the spec defaults for the colour count: sigmas
    (0.9, 0.9, 0.6) and weights (0.294, 0.118, 0.588); mono: sigma 0.4, weight 1 and no demosaic.
    """
    clt = np.asarray(clt, dtype=np.float64)
    cams, colours = clt.shape[-5], clt.shape[-4]
    if lpf_sigmas is None:
        lpf_sigmas = tables.TEXTURE_SIGMAS if colours == 3 else (tables.TEXTURE_SIGMA_MONO,)
    if colour_weights is None:
        colour_weights = tables.TEXTURE_COLOUR_WEIGHTS if colours == 3 else (1.0,)
    offsets = np.asarray(camera_offsets, dtype=np.float64)
    lpf = np.stack([tables.lpf(s) for s in lpf_sigmas])  # (colours, 8, 8)
    t = imclt(clt * lpf[:, None])  # (T..., cams, colours, 16, 16)
    w2 = operators.window_squared()
    if colours == 3:
        u = t / w2
        m = np.stack([demosaic_interior(u[..., k, :, :], G_FILTER if k == 2 else RB_FILTER) for k in range(3)], -3)
        m = shot_compress(m, scale_shot, min_shot) * w2
    else:
        m = t
    cw = np.asarray(colour_weights, dtype=np.float64)[:, None, None]
    xi = 1.0 / (2.0 * diff_sigma**2)
    eps = tables.TEXTURE_WEIGHT_FLOOR
    # a. pairwise agreement
    weight = np.zeros(t.shape[:-4] + (cams, 16, 16))
    for a in range(cams):
        for b in range(a + 1, cams):
            dist2 = np.sum((offsets[b] - offsets[a]) ** 2)
            d = np.sum(cw * ((m[..., a, :, :, :] - m[..., b, :, :, :]) / w2) ** 2, axis=-3)
            v = np.exp(-xi * d / dist2) + eps
            weight[..., a, :, :] += v
            weight[..., b, :, :] += v
    # b. mean of the two best cameras (first index wins ties)
    order = np.argsort(-weight, axis=-3, kind="stable")
    best, second = order[..., 0:1, :, :], order[..., 1:2, :, :]
    wb = np.take_along_axis(weight, best, axis=-3)
    ws = np.take_along_axis(weight, second, axis=-3)
    mb = np.take_along_axis(m, best[..., None, :, :], axis=-4)[..., 0, :, :, :]
    ms = np.take_along_axis(m, second[..., None, :, :], axis=-4)[..., 0, :, :, :]
    mean = (wb * mb + ws * ms) / (wb + ws)  # (T..., colours, 16, 16)
    # c. each camera's agreement with that mean
    d = np.sum(cw * ((m - mean[..., None, :, :, :]) / w2) ** 2, axis=-3)
    weight = np.exp(-xi * d) + eps  # (T..., cams, 16, 16)
    # d. dust removal: the least agreeing camera is suppressed, the others boosted
    if dust_remove:
        worst = np.argmin(weight, axis=-3)[..., None, :, :]
        w_worst = np.take_along_axis(weight, worst, axis=-3)
        mu = (weight.sum(axis=-3, keepdims=True) - w_worst) / (cams - 1)
        boosted = weight * (1.0 + w_worst * (mu - w_worst) / ((cams - 1) * mu**2))
        is_worst = np.arange(cams)[:, None, None] == worst
        weight = np.where(is_worst, w_worst * w_worst / mu, boosted)
    # e. colour and alpha
    total = weight.sum(axis=-3)
    colour = np.sum(weight[..., None, :, :] * t, axis=-4) / total[..., None, :, :]
    alpha = w2 * total / cams
    return np.concatenate([colour, alpha[..., None, :, :]], axis=-3)


def fade_ramp() -> np.ndarray:
    """f(i) = (1 - cos(pi (i + 1/2) / 16)) / 2 for i = 0..15: ~0 at i = 0, ~1 at i = 15."""
    return 0.5 * (1.0 - np.cos(np.pi * (np.arange(16) + 0.5) / 16))


def alpha_fade(north: bool, east: bool, south: bool, west: bool) -> np.ndarray:
    """Fade ``(16, 16)`` of a tile given which neighbours contribute (§7.4): one neighbour -> a ramp towards
    it; two adjacent -> the max of their ramps; none, two opposite, three or four -> 1 (a lone tile is kept)."""
    f = fade_ramp()
    r = np.arange(16)[:, None]
    c = np.arange(16)[None, :]
    ramps = {"n": f[15 - r] + 0 * c, "e": f[c] + 0 * r, "s": f[r] + 0 * c, "w": f[15 - c] + 0 * r}
    have = [k for k, on in zip("nesw", (north, east, south, west)) if on]
    if len(have) == 1:
        return ramps[have[0]]
    if len(have) == 2 and set(have) not in ({"n", "s"}, {"e", "w"}):
        return np.maximum(ramps[have[0]], ramps[have[1]])
    return np.ones((16, 16))


def texture_image(rgba, contributing, height: int, width: int, output_gain: float = tables.TEXTURE_OUTPUT_GAIN):
    """Overlap-add RGBA tiles ``(tiles_y, tiles_x, ch, 16, 16)`` of the contributing tiles ``(tiles_y, tiles_x)``
    into an image ``(ch, height, width)`` with the alpha fade; colour channels x ``output_gain``."""
    rgba = np.asarray(rgba, dtype=np.float64)
    ty_n, tx_n = contributing.shape
    faded = np.zeros_like(rgba)
    for ty in range(ty_n):
        for tx in range(tx_n):
            if not contributing[ty, tx]:
                continue
            n = ty == 0 or contributing[ty - 1, tx]
            s = ty + 1 == ty_n or contributing[ty + 1, tx]
            w = tx == 0 or contributing[ty, tx - 1]
            e = tx + 1 == tx_n or contributing[ty, tx + 1]
            faded[ty, tx] = rgba[ty, tx] * alpha_fade(n, e, s, w)
    image = overlap_add(np.moveaxis(faded, 2, 0), height, width)
    image[:-1] *= output_gain
    return image
