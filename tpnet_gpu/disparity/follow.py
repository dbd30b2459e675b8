"""The first stage of a frame that follows another (video, issue 39 item 1): instead of sweeping the whole range,
every tile is read once at its answer in the previous frame, and only the tiles that lost a clear answer there
are swept again (disparity.md §11).

A tile "lost" its answer when the previous frame measured it (strength >= ``EngineConfig.min_strength``) and the
pass at that answer no longer shows a peak within reach: the surface moved more than a pass can read
(``EngineConfig.reach``), or something new covers the tile. Tiles the previous frame could not measure either
(sky, no texture) are not swept: the per-frame search would find no peak there either. What a followed frame
cannot see - a new object in front of such a tile - comes back with the next full search, which a stream runs
every ``REFRESH`` frames.

Where the rig moves forward the previous answers are carried by that motion first (``carried``): a point at
disparity d comes nearer by the factor 1 / (1 - k d) (k = t_z / (B f), 1/px, the rig's forward step over baseline
times focal length) in disparity and in its distance from the image centre. k is measured on each followed frame
(``measured_motion``: the change of 1/d between the start and the answer, a weighted median over the tiles) and
used on the next (the rig keeps its speed). Sideways motion and turns are not modelled: at a fixed pixel they
leave a surface's disparity as it was, and the lost tiles' sweep catches its edges (disparity.md §11).

A frame that does not continue the one before - a cut, another camera's feed - is searched in full: its first
camera's 8x8 means (``view``) correlate with the frame before's less than ``CUT_ZNCC`` where both are finite
(``continues``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from tpnet_gpu.disparity.results import DisparityResult
from tpnet_gpu.layout import TILE_CENTRE, TILE_STRIDE

REFRESH = 8  # a stream runs the full search on every REFRESH-th frame (and on its first)
# px: a followed frame's refinement stops where a pass moves a tile less than this (EngineConfig.tolerance, 0.03,
# on searched frames). Chosen on tuning sequences (`bench/accuracy/bench_video.sequence`, seed 500, scenes 1-3,
# 6 frames, 150 mm steps; not the bench's held-out 10000+), the followed frames' tile passes / gross / own-inlier
# RMSE at 0.1: 1.59 / 13.0 % / 0.108 px; 0.2: 1.43 / 12.9 % / 0.108; 0.3: 1.38 / 13.0 % / 0.109 (every frame
# searched: 4.12 / 13.6 % / 0.108): the first pass, already at the last frame's answer, is read near its peak
FOLLOW_TOLERANCE = 0.2
# the most a carried answer's disparity may grow or shrink in one frame: a k measured across a cut (a new scene)
# or on few tiles must not throw the starts out of the range they were read in
CARRY_BOUNDS = (2.0 / 3.0, 1.5)
MOTION_TILES = 16  # tiles with answers in both frames needed to measure k (else the last k is kept)
MOTION_LEAST = 1.0  # px: tiles nearer to infinity say little of k (their 1/d is noise)
# the ZNCC of two frames' first-camera 8x8 means below which the second is a cut, searched in full. Tuning
# sequences (seed 500, 640x480 quad, scenes 0-2): consecutive frames 0.996-0.999 at 150 mm steps, 0.919-0.954 at
# 1500 mm; first frames of different scenes (scenes 0-3, 6 pairs) 0.056-0.483
CUT_ZNCC = 0.7


def view(frames: torch.Tensor) -> torch.Tensor:
    """``(H // 8, W // 8)``: the 8x8 means of the first camera of ``frames (cams, H, W)`` (a Bayer cell's colours
    alike): what ``continues`` compares."""
    return F.avg_pool2d(frames[:1, None], TILE_STRIDE)[0, 0]


def continues(previous: DisparityResult | None, seen: torch.Tensor) -> DisparityResult | None:
    """``previous`` if the frame whose ``view`` is ``seen`` continues it (ZNCC >= ``CUT_ZNCC`` over the cells
    finite in both: masked pixels, NaN, do not end a video), else None: a cut - also where half the cells or more
    are not finite in one of them, or either view is flat."""
    if previous is None or previous.view is None:
        return previous
    both = torch.isfinite(previous.view) & torch.isfinite(seen)
    if 2 * int(both.sum()) <= both.numel():
        return None
    a, b = previous.view[both], seen[both]
    a, b = a - a.mean(), b - b.mean()
    return previous if float((a * b).sum() / (a.norm() * b.norm())) >= CUT_ZNCC else None  # flat: NaN, a cut


def start_of(previous: DisparityResult) -> torch.Tensor:
    """``(ty, tx)``: the previous frame's answer (its first stage's where refinement left none), carried by the
    rig's forward motion ``previous.motion``."""
    return carried(_answer(previous), previous.motion)


def _answer(previous: DisparityResult) -> torch.Tensor:
    return torch.where(torch.isfinite(previous.disparity), previous.disparity, previous.search)


def carried(disparity: torch.Tensor, motion: float) -> torch.Tensor:
    """``(ty, tx)``: ``disparity (ty, tx)`` as the rig sees it after a forward step ``motion`` (k, 1/px): each
    tile's d becomes d / (1 - k d) and moves that much further from the image centre; where two land on one tile
    the nearer (larger d) wins; a tile nothing lands on keeps its own answer, scaled. NaN stays NaN; ``motion``
    0 returns ``disparity`` itself."""
    if motion == 0:
        return disparity
    ty, tx = disparity.shape
    scale = (1.0 / (1.0 - motion * disparity)).clamp(*CARRY_BOUNDS)  # NaN for NaN; 1 - k d <= 0 clamps
    scaled = disparity * scale
    # tile centres and the image centre (W / 2, H / 2), px; a moved centre lands on the tile nearest to it
    y = (TILE_STRIDE * torch.arange(ty, device=disparity.device, dtype=disparity.dtype) + TILE_CENTRE)[:, None]
    x = (TILE_STRIDE * torch.arange(tx, device=disparity.device, dtype=disparity.dtype) + TILE_CENTRE)[None, :]
    cy, cx = TILE_STRIDE * ty / 2, TILE_STRIDE * tx / 2
    row = torch.round(((y - cy) * scale + cy - TILE_CENTRE) / TILE_STRIDE)
    col = torch.round(((x - cx) * scale + cx - TILE_CENTRE) / TILE_STRIDE)
    inside = torch.isfinite(scaled) & (row >= 0) & (row < ty) & (col >= 0) & (col < tx)
    landed = torch.full((ty * tx,), float("-inf"), device=disparity.device, dtype=disparity.dtype)
    index = (row * tx + col)[inside].long()
    landed.scatter_reduce_(0, index, scaled[inside], "amax")
    landed = landed.view(ty, tx)
    return torch.where(torch.isfinite(landed), landed, scaled)


def measured_motion(previous: DisparityResult, disparity: torch.Tensor, strength: torch.Tensor,
                    min_strength: float) -> float:
    """k (1/px) of the frame just followed from ``previous``, its answers ``disparity (ty, tx)``: from
    ``previous.motion``, twice k += what ``previous``'s answers carried by k missed, 1/carried - 1/d, over the tiles
    measured (``strength`` >= ``min_strength``) at ``MOTION_LEAST`` px or more, its median weighted by d^2 (the
    noise of 1/d falls as 1/d^2). Twice: at a fixed pixel a near surface's edge moves outward over the background
    as the rig nears it, so the change there is more than k; carried by the first estimate, the edges meet."""
    answer, motion = _answer(previous), previous.motion
    for _ in range(2):
        start = carried(answer, motion)
        ok = (strength >= min_strength) & (start >= MOTION_LEAST) & (disparity >= MOTION_LEAST)  # False for NaN
        if int(ok.sum()) < MOTION_TILES:
            return motion
        d = disparity[ok].double()
        missed = 1.0 / start[ok].double() - 1.0 / d
        order = torch.argsort(missed)
        weight = torch.cumsum((d * d)[order], 0)
        motion += float(missed[order][int(torch.searchsorted(weight, 0.5 * weight[-1]))])
    return motion


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
