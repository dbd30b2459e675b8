"""Golden reference: 2-D phase correlation of tile pairs (tile_processor.md §6). Float64, NumPy.

Sign (§6.4): if the second tile's content equals the first's moved by (+a_x, +a_y) (right / down) and both
use the same centre, the correlation peaks at lag (m_y, m_x) ~ (a_y, a_x). Output row = m_y + r, column = m_x + r.
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import operators, tables
from tpnet_gpu.reference.products import correlation_product


def correlate_fd(
    first,
    second,
    *,
    colour_weights=None,
    fat_zero: float = tables.CORR_FAT_ZERO,
    sigma_rb: float = tables.CORR_SIGMA_RB,
    sigma_corr: float | None = None,
) -> np.ndarray:
    """Colour-weighted, fat-zero normalised, low-passed correlation spectrum of tile pairs (§6.2).

    first, second: ``(..., C, 4, 8, 8)`` CLT tiles with C = 3 (R, B, G) or C = 1 (mono).
    Colour: X = w_R P_R + w_B P_B, X *= L(sigma_rb), X += w_G P_G; mono: X = w P. Then per frequency
    X_q /= sqrt(fat_zero^2 + sum_q' X_q'^2) and X *= L(sigma_corr). Defaults: weights (0.25, 0.25, 0.5) or (1,),
    sigma_corr 0.9 (colour) or 0.15 (mono). Returns ``(..., 4, 8, 8)``.
    """
    first = np.asarray(first, dtype=np.float64)
    second = np.asarray(second, dtype=np.float64)
    if first.shape[-4:] != second.shape[-4:] or first.shape[-4] not in (1, 3) or first.shape[-3:] != (4, 8, 8):
        raise ValueError(
            f"first, second: expected (..., C, 4, 8, 8) with C 1 or 3 and equal C, got {first.shape}, {second.shape}"
        )
    colours = first.shape[-4]
    if colour_weights is None:
        colour_weights = tables.CORR_COLOUR_WEIGHTS if colours == 3 else (1.0,)
    if sigma_corr is None:
        sigma_corr = tables.CORR_SIGMA if colours == 3 else tables.CORR_SIGMA_MONO
    if len(colour_weights) != colours:
        raise ValueError(f"colour_weights: expected {colours} values, got {len(colour_weights)}")
    products = correlation_product(first, second)  # (..., C, 4, 8, 8)
    if colours == 3:
        acc = colour_weights[0] * products[..., 0, :, :, :] + colour_weights[1] * products[..., 1, :, :, :]
        acc = acc * tables.lpf(sigma_rb)
        acc = acc + colour_weights[2] * products[..., 2, :, :, :]
    else:
        acc = colour_weights[0] * products[..., 0, :, :, :]
    norm = np.sqrt(fat_zero**2 + np.sum(acc**2, axis=-3, keepdims=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        acc = np.where(norm > 0, acc / np.where(norm > 0, norm, 1.0), 0.0)
    return acc * tables.lpf(sigma_corr)


def corr_to_pixels(x, radius: int = tables.CORR_RADIUS) -> np.ndarray:
    """Correlation spectrum ``(..., 4, 8, 8)`` to the pixel-domain correlation ``(..., 2r+1, 2r+1)`` (§6.3).

    DCT-II-e / DST-II-e along columns (sine iff q>>1) and rows (sine iff q&1), then the quadrant unfold with
    factor 1/4, giving R(m_y, m_x) = 1/16 sum_q sum X_q[ky, kx] phi_{q>>1}(omega_ky m_y) phi_{q&1}(omega_kx m_x).
    Lag +-8 is dropped, so ``radius`` <= 7.
    """
    if not 0 <= radius <= tables.CORR_RADIUS:
        raise ValueError(f"radius: expected 0..{tables.CORR_RADIUS}, got {radius}")
    x = np.asarray(x, dtype=np.float64)
    a = operators.lag_operators(radius)  # (2, 2r+1, 8): 1/2 transform then unfold, per axis
    return sum(a[q >> 1] @ x[..., q, :, :] @ a[q & 1].T for q in range(4))


def crop_centre(corr, radius: int = tables.NET_RADIUS) -> np.ndarray:
    """Centre ``(2 radius + 1)^2`` crop of square correlation tiles ``(..., S, S)`` (9x9 for the network)."""
    corr = np.asarray(corr)
    half = corr.shape[-1] // 2
    if radius > half:
        raise ValueError(f"radius: expected <= {half} for tiles of side {corr.shape[-1]}, got {radius}")
    return corr[..., half - radius : half + radius + 1, half - radius : half + radius + 1]


def correlate(first, second, *, radius: int = tables.CORR_RADIUS, **kwargs) -> np.ndarray:
    """Pixel-domain phase correlation ``(..., 2r+1, 2r+1)`` of CLT tile pairs ``(..., C, 4, 8, 8)``."""
    return corr_to_pixels(correlate_fd(first, second, **kwargs), radius)


def network_layers(corr, pairs=tables.QUAD_PAIRS, *, offset: float = tables.NET_CORR_OFFSET) -> np.ndarray:
    """The network's 4 correlation layers ``(..., 4, 9, 9)`` from the quad's 6 pair tiles ``(..., 6, S, S)``.

    network.md §1 / geometry_and_lma.md B.5: [hor, vert, diag-main, diag-other] where hor = combine(pair 0,
    pair 1), vert = combine(pair 2, pair 3) (not transposed), and combine(a, b) = sqrt((a + o)(b + o)) - o if
    a > 0 and b > 0 else 0 (o = ``offset``; o < 0 gives the plain mean (a + b) / 2). Centre 9x9 of each.
    """
    if tuple(map(tuple, pairs)) != tables.QUAD_PAIRS:
        raise ValueError(f"pairs: the network layers need the quad's 6 pairs {tables.QUAD_PAIRS}, got {pairs}")
    c = crop_centre(np.asarray(corr, dtype=np.float64), tables.NET_RADIUS)

    def combine(a, b):
        if offset < 0:
            return 0.5 * (a + b)
        both = (a > 0) & (b > 0)
        return np.where(both, np.sqrt(np.maximum((a + offset) * (b + offset), 0.0)) - offset, 0.0)

    parts = [combine(c[..., 0, :, :], c[..., 1, :, :]), combine(c[..., 2, :, :], c[..., 3, :, :]),
             c[..., 4, :, :], c[..., 5, :, :]]
    return np.stack(parts, axis=-3)


def group_layers(corr, groups, *, offset: float = tables.NET_CORR_OFFSET) -> np.ndarray:
    """The network layers of any rig ``(..., G, 9, 9)``, float64, from pair tiles ``(..., P, S, S)`` and its
    direction groups ``((lag, ((pair, mirrored), ...)), ...)`` (``disparity.pairs.direction_groups``).

    Per group, on the centre 9x9 of each member (point-mirrored, both axes flipped, where ``mirrored``): one
    member as it is; n members ``(prod (c_i + o))^(1/n) - o`` where all are positive, else 0 (o < 0: the plain
    mean) - for two members :func:`network_layers`' combine.
    """
    c = crop_centre(np.asarray(corr, dtype=np.float64), tables.NET_RADIUS)
    out = []
    for _, members in groups:
        tiles = np.stack([np.flip(c[..., p, :, :], (-2, -1)) if m else c[..., p, :, :] for p, m in members])
        if len(members) == 1:
            out.append(tiles[0])
        elif offset < 0:
            out.append(tiles.mean(axis=0))
        else:
            root = np.prod(np.maximum(tiles + offset, 0.0), axis=0) ** (1.0 / len(members))
            out.append(np.where(np.all(tiles > 0, axis=0), root - offset, 0.0))
    return np.stack(out, axis=-3)
