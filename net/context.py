"""TPNET's context step (network.md §13): each tile's disparity becomes the strength-weighted mean of the tiles of
its 5x5 neighbourhood that lie on its own surface (within ``CONTEXT_BAND`` px of it, itself included).

The network's answers on one surface scatter about it independently enough that their local mean is closer to
the truth than each alone (network.md §10: the neighbours hold information stage 2 does not use). The surface
is the tile's own, not the neighbourhood's majority, so a tile beside a depth edge averages only with its own
side and the edge stays where it is; a plane's mean over a symmetric window is its centre value, so slanted
surfaces are not biased away from edges. Runs on the disparity's device, no host copies.
"""

from __future__ import annotations

import torch

from tpnet_gpu.disparity.grid import surface_mean

# px: the neighbours within this of a tile count as its surface. Measured with the v4 weights, one pass, on 32
# rendered 640x480 scenes of seeds 20000+ (neither training nor held out; bench/accuracy/bench_network_context.py),
# own-inlier RMSE as a ratio to the engine's, tuning scenes 0-15 / check scenes 16-31:
# flat 0.630 -> 0.458x / 0.693 -> 0.554x, edge 1.048 -> 0.847x / 0.981 -> 0.854x, all 0.902 -> 0.789x /
# 0.887 -> 0.799x; strict gross tiles (all classes) 2637 -> 2638 / 2389 -> 2380. A 0.25 px band kept less of the
# gain (flat 0.493x on the tuning scenes), 1 px lost flat tiles to their neighbours (0.502x); the 3x3 median of
# §10 left edges at 1.016x; weights from the engine's confidence instead of its strength made 7 more tiles gross;
# applied between two passes, the second pass undid most of it (flat 0.512x).
CONTEXT_BAND = 0.5
# tiles: the window's side. With v4, 5x5 scored better on RMSE (tuning: flat 0.435x, edge 0.784x) but made 22
# instead of 17 of the engine's right tiles gross on the tuning scenes, so 3x3 was kept. With the v5 weights, the
# same 32 scenes, 3x3 -> 5x5: flat 0.431 -> 0.414x / 0.542 -> 0.518x, edge 0.806 -> 0.746x / 0.821 -> 0.767x,
# all 0.793 -> 0.762x / 0.789 -> 0.761x; tiles made gross 15 -> 18 / 47 -> 48 (network.md §13).
CONTEXT_SIZE = 5


def context_step(disparity: torch.Tensor, strength: torch.Tensor) -> torch.Tensor:
    """``(tiles_y, tiles_x)``: each finite tile of ``disparity (tiles_y, tiles_x)`` (px, NaN = none) replaced by
    the ``strength``-weighted mean of the finite tiles of its ``CONTEXT_SIZE`` x ``CONTEXT_SIZE`` neighbourhood
    (itself included) within ``CONTEXT_BAND`` px of it; ``strength (tiles_y, tiles_x)`` >= 0 (the engine's
    correlation strength). A tile whose surface weighs 0 keeps its value; NaN tiles stay NaN and weigh nothing."""
    if disparity.dim() != 2 or strength.shape != disparity.shape:
        raise ValueError(f"strength: expected the shape of disparity, a (tiles_y, tiles_x) grid "
                         f"{tuple(disparity.shape)}, got {tuple(strength.shape)}")
    mean, total = surface_mean(disparity, strength, disparity, CONTEXT_BAND, CONTEXT_SIZE)
    return torch.where(total > 0, mean, disparity)  # a NaN tile has no neighbour within the band: total 0
