"""The first stage of a frame that follows another (video, issue 39 item 1): instead of sweeping the whole range,
every tile is read once at its answer in the previous frame, and only the tiles that lost a clear answer there
are swept again (disparity.md §11).

A tile "lost" its answer when the previous frame measured it (strength >= ``EngineConfig.min_strength``) and the
pass at that answer no longer shows a peak within reach: the surface moved more than a pass can read
(``EngineConfig.reach``), or something new covers the tile. Tiles the previous frame could not measure either
(sky, no texture) are not swept: the per-frame search would find no peak there either. What a followed frame
cannot see - a new object in front of such a tile - comes back with the next full search, which a stream runs
every ``REFRESH`` frames.
"""

from __future__ import annotations

import torch

from tpnet_gpu.disparity.results import DisparityResult

REFRESH = 8  # a stream runs the full search on every REFRESH-th frame (and on its first)
# px: a followed frame's refinement stops where a pass moves a tile less than this (EngineConfig.tolerance, 0.03,
# on searched frames). Chosen on tuning sequences (`bench/accuracy/bench_video.sequence`, seed 500, scenes 1-3,
# 6 frames, 150 mm steps; not the bench's held-out 10000+), the followed frames' tile passes / gross / own-inlier
# RMSE at 0.1: 1.59 / 13.0 % / 0.108 px; 0.2: 1.43 / 12.9 % / 0.108; 0.3: 1.38 / 13.0 % / 0.109 (every frame
# searched: 4.12 / 13.6 % / 0.108): the first pass, already at the last frame's answer, is read near its peak
FOLLOW_TOLERANCE = 0.2


def start_of(previous: DisparityResult) -> torch.Tensor:
    """``(ty, tx)``: the previous frame's answer, its first stage's where refinement left none."""
    return torch.where(torch.isfinite(previous.disparity), previous.disparity, previous.search)


def follow(engine, previous: DisparityResult) -> tuple[torch.Tensor, torch.Tensor, float]:
    """``engine.search()``'s ``(search, margin, passes)`` for the frame loaded into ``engine``'s processor,
    from ``previous`` (that engine's result on the frame before) instead of the full first stage."""
    cfg, volume = engine.config, engine.volume
    volume.reset()
    start = torch.nan_to_num(start_of(previous), nan=engine.d_min)
    engine._sweep(engine.tp, [start], volume)  # every tile at its previous answer: one pass
    engine._keep_first(start)
    passes = 1.0
    first = engine.first
    holds = torch.isfinite(first.residual) & (first.strength >= cfg.min_strength) & \
        (first.residual.abs() <= cfg.reach - 1.0)
    lost = (previous.strength >= cfg.min_strength) & ~holds
    share = float(lost.float().mean())
    if share > 0:
        sweep = engine._full_sweep()
        engine._sweep(engine.tp, sweep, volume, active=lost)
        passes += len(sweep) * share
    found, margin = engine._choose(volume)
    return found, margin, passes
