"""Motion vectors: per-tile 2-D flow from one frame to the next, measured by the tile processor (issue 17 item 3;
motion_and_surfaces.md §1).

Frames t and t+1 of the same camera are two "cameras" of one processor, correlated as a pair: frame t's tile sits
on the tile grid (8 tx + 4, 8 ty + 4) of the camera's own image, frame t+1's at the grid plus the current flow
estimate, so the pair correlation peaks at the residual flow (README: a content shift (a_x, a_y) of the second
camera peaks at lag (a_y, a_x)). As the disparity engine's refinement: re-centre each tile by its estimate,
re-correlate, add the residual (``Peak2D``: the combined correlation's 2-D peak), on the tiles whose step is
still above ``tolerance``. Each tile starts twice, from ``init`` and from the flow of 2x2-binned frames scaled
up (``flow_starts``: near objects move beyond one correlation's reach), keeping the stronger answer; tiles more
than ``outlier`` px from their neighbours' median flow are measured again from that median; what is still apart
from its neighbours, or matches elsewhere as well (``Peak2D.rival``), or disagrees with the flow measured back
from frame t+1 (``backward``), is dropped. Several cameras (a rig's
frames at t and t+1) are several such pairs, each camera's tiles centred where the disparity engine's maps say
the virtual camera's tile sees (``flow_align``), combined per tile (``combine_pairs``: a false peak of one
camera is suppressed by the others) into the rig's flow.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from tpnet_gpu.camera import Rig, grid_centres
from tpnet_gpu.disparity.engine import DisparityEngine, correlation_for, reference_scale
from tpnet_gpu.disparity.grid import ring_median
from tpnet_gpu.disparity.measure import Peak2D, row_chunks
from tpnet_gpu.disparity.pairs import combine_pairs
from tpnet_gpu.flow.align import Alignment
from tpnet_gpu.flow.starts import bin_frames, coarse_size, scaled_start
from tpnet_gpu.layout import CORR_RADIUS
from tpnet_gpu.processor import TileProcessor


OUTLIER_SUPPORT = 5  # measured neighbours (of 8) that make a tile's disagreement with their median an outlier


@dataclass(frozen=True)
class FlowConfig:
    """Flow settings (px). At most ``iterations`` correlations per tile pass; a tile is done when its step is below
    ``tolerance``; a measurement counts where its strength >= ``min_strength`` and its residual is within ``reach``
    (the first pass finds flows up to ``reach`` from ``init``); ``outlier``: the distance from the 8 neighbours'
    median flow that sends a tile round again from that median. ``search``: tiles without a trusted measurement from
    ``init`` are tried again from the 8 starts ``reach`` px around it (flows up to 2 ``reach``), keeping the
    strongest answer. ``levels``: 2x2-binned levels whose flow, scaled up, is a second start of every tile
    (``flow_starts``; each level doubles the flows found, and blurs a fine repeating texture away; 0: none; 2
    levels: a tuning scene, seed 1200, up 150 mm + pan, 13.6 -> 5.5 % gross, the others unchanged). ``unique``: a
    flow is dropped where the correlation at it has another peak of at least this share of its own
    (``Peak2D.rival``: a periodic or 1-D texture, the match is ambiguous; 1 keeps all). ``backward``: the flow from
    frame t+1 back to frame t is measured too, and tiles where the two do not sum to within ``outlier`` px are
    dropped (``FlowEstimator.disagree``: occlusions, false matches; 3 tuning scenes, the 5 motions: mean gross 2.4
    -> 1.7 % for one camera, 2.1 -> 1.3 % for 4, coverage -1 point; twice the cost, the engine's maps shared)."""

    iterations: int = 6
    tolerance: float = 0.02
    min_strength: float = 0.1
    reach: float = 6.0
    outlier: float = 1.0
    search: bool = True
    levels: int = 2
    unique: float = 0.6
    backward: bool = True

    def __post_init__(self):
        for name, least in (("iterations", 1), ("levels", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise ValueError(f"FlowConfig.{name}: expected an int >= {least}, got {value!r}")
        if not (isinstance(self.unique, (int, float)) and 0 < self.unique <= 1):
            raise ValueError(f"FlowConfig.unique: expected a number in (0, 1], got {self.unique!r}")
        for name in ("tolerance", "reach", "outlier"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"FlowConfig.{name}: expected a finite number > 0, got {value!r}")
        if not (isinstance(self.min_strength, (int, float)) and np.isfinite(self.min_strength)
                and self.min_strength >= 0):
            raise ValueError(f"FlowConfig.min_strength: expected a finite number >= 0, got {self.min_strength!r}")
        if self.reach > CORR_RADIUS - 1:
            raise ValueError(f"FlowConfig.reach: expected at most {CORR_RADIUS - 1} px (the correlation's lags), "
                             f"got {self.reach!r}")


@dataclass(frozen=True)
class FlowResult:
    """One frame pair's motion vectors, torch on the estimator's device.

    Attributes:
        flow: ``(tiles_y, tiles_x, 2)`` (x, y) px: where tile (tx, ty)'s content at (8 tx + 4, 8 ty + 4) of frame
            t is in frame t+1, minus that centre; NaN where not valid.
        confidence: ``(tiles_y, tiles_x)`` the final measurement's correlation strength (0 where none).
        valid: ``(tiles_y, tiles_x)`` bool: a trusted measurement with both windows inside the image.
        tile_passes: tiles x cameras processed, in full passes of both frames.
    """

    flow: torch.Tensor
    confidence: torch.Tensor
    valid: torch.Tensor
    tile_passes: float


def _frames(name: str, value) -> torch.Tensor:
    t = value if isinstance(value, torch.Tensor) else torch.as_tensor(np.asarray(value))
    if t.dim() == 2:
        t = t[None]
    if t.dim() != 3 or t.dtype.is_complex or t.dtype == torch.bool:
        raise ValueError(f"{name}: expected real frames (height, width) or (cams, height, width), "
                         f"got {t.dtype} of shape {tuple(t.shape)}")
    return t


class FlowEstimator:
    """Flow of frames ``(cams, height, width)`` (or ``(height, width)``) of ``cams`` cameras (module docstring).

    Args:
        cfa: Bayer pattern of raw frames, or None (mono images).
        config: flow settings.
        rig: the rig of ``cams`` > 1 cameras (default: the ideal quad of this frame size), whose disparity
            engine aligns the cameras' tiles (``flow_align``); the flow is then the rig's virtual camera's
            (camera 0's for a rig ``referenced_to(0)``). None for one camera.
        device, backend: the tile processor's (``TileProcessor``).
    """

    def __init__(self, height: int, width: int, *, cams: int = 1, cfa: str | None = "GRBG",
                 config: FlowConfig = FlowConfig(), rig: Rig | None = None, device: str | None = None,
                 backend: str | None = None):
        if isinstance(cams, bool) or not isinstance(cams, int) or cams < 1:
            raise ValueError(f"cams: expected an int >= 1, got {cams!r}")
        if cams == 1 and rig is not None:
            raise ValueError("rig: expected None for one camera (a rig aligns several), got a rig")
        if cams > 1:
            rig = rig if rig is not None else Rig(width=width, height=height)
            if not isinstance(rig, Rig) or rig.cams != cams:
                raise ValueError(f"rig: expected a Rig of {cams} cameras (cams), got {rig!r}")
        self.cams, self.config = cams, config
        # frame t of camera k is processor camera k, frame t+1 is camera cams + k; the offsets only name them
        # (every centre is given), distinct so that each pair has a direction
        offsets = [(float(k), 0.0) for k in range(cams)] + [(float(k), 1.0) for k in range(cams)]
        pairs = tuple((k, cams + k) for k in range(cams))
        self.tp = TileProcessor(height, width, camera_offsets=offsets, pairs=pairs, cfa=cfa,
                                config=correlation_for(cfa), device=device, backend=backend)
        self.device = self.tp.torch_device
        self.grid = (self.tp.tiles_y, self.tp.tiles_x)
        self.peak = Peak2D(self.device, reach=config.reach, widen=cfa is None)
        self.centres = torch.from_numpy(grid_centres(*self.grid)).reshape(-1, 1, 2).float().to(self.device)
        # several cameras: their tiles aligned by the disparity engine's maps of both frames
        self.engine = None if cams == 1 else DisparityEngine(height, width, rig=rig, cfa=cfa, device=device,
                                                               backend=backend)
        self.align = None if cams == 1 else Alignment(rig, self.grid, self.device)
        size = coarse_size(height, width) if config.levels > 0 else None
        # the coarse levels measure the first camera alone: a start, refined with every camera here
        self.coarse = None if size is None else FlowEstimator(
            *size, cams=1, cfa=None, config=replace(config, levels=config.levels - 1), device=device,
            backend=backend)

    def load(self, frame_t, frame_t1) -> None:
        """Stage both frames (scaled together to the engine's reference level) in the processor."""
        a, b = _frames("frame_t", frame_t), _frames("frame_t1", frame_t1)
        expected = (self.cams, self.tp.height, self.tp.width)
        for name, t in (("frame_t", a), ("frame_t1", b)):
            if tuple(t.shape) != expected:
                raise ValueError(f"{name}: expected frames of shape {expected} (cams, height, width), "
                                 f"got {tuple(t.shape)}")
        staging = self.tp.staging
        staging[: self.cams].copy_(a)
        staging[self.cams :].copy_(b)
        staging.mul_(reference_scale(staging))
        self.tp.load(staging)

    def _measure(self, flow: torch.Tensor, active: torch.Tensor, rival: bool = False):
        """Residual flow ``(T, 2)`` and strength ``(T,)`` of the loaded frames with frame t+1's tiles at
        ``flow (T, 2)`` (``active (T,)`` tiles only; NaN / 0 elsewhere); with ``rival``, also ``Peak2D.rival``
        of the correlation ``(T,)`` (0 where not measured)."""
        if self.align is not None:
            centres = self.align.centres(flow)
        else:
            centres = torch.cat([self.centres, self.centres + torch.nan_to_num(flow, nan=0.0)[:, None, :]], dim=1)
        result = self.tp.measure(centres=centres, active=active)
        tiles = flow.shape[0]
        residual = torch.full((tiles, 2), float("nan"), device=self.device)
        strength = torch.zeros((tiles,), device=self.device)
        rivals = torch.zeros((tiles,), device=self.device)
        side = 2 * CORR_RADIUS + 1
        for index, corr in row_chunks(result.corr, torch.nonzero(active & result.valid, as_tuple=True)[0]):
            combined = combine_pairs(corr.reshape(corr.shape[0], corr.shape[1], -1)).reshape(-1, side, side)
            residual[index], strength[index] = self.peak.measure(combined)
            if rival:
                rivals[index] = self.peak.rival(combined)
        return (residual, strength, rivals) if rival else (residual, strength)

    def refine(self, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, float]:
        """Iterated re-correlation from ``start (T, 2)`` (NaN rows: not measured): ``(flow, strength, passes)``."""
        cfg = self.config
        f = start.clone()
        active = torch.isfinite(f).all(dim=1)
        flow = torch.full_like(f, float("nan"))
        strength = torch.zeros(f.shape[0], device=self.device)
        passes = 0.0
        for _ in range(cfg.iterations):
            if not bool(active.any()):
                break
            r, s = self._measure(f, active)
            passes += float(active.float().mean())
            step = r.norm(dim=1)
            good = active & torch.isfinite(step) & (s >= cfg.min_strength) & (step <= cfg.reach)
            f = torch.where(good[:, None], f + r, f)
            flow = torch.where(good[:, None], f, flow)
            strength = torch.where(good, s, strength)
            active = good & (step >= cfg.tolerance)
        return flow, strength, passes

    def search(self, start: torch.Tensor, flow: torch.Tensor, strength: torch.Tensor):
        """The tiles ``refine`` left unmeasured, refined again from each of 8 starts ``reach`` px around
        ``start (T, 2)``; the strongest answer is kept (``(flow, strength, passes)``)."""
        passes = 0.0
        missing = ~torch.isfinite(flow).all(dim=1)
        step = self.config.reach
        for dx, dy in ((-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)):
            if not bool(missing.any()):
                break
            offset = torch.tensor([dx * step, dy * step], device=self.device)
            nan = torch.full_like(start, float("nan"))
            second, s2, more = self.refine(torch.where(missing[:, None], start + offset, nan))
            passes += more
            better = missing & torch.isfinite(second).all(dim=1) & (s2 > strength)
            flow = torch.where(better[:, None], second, flow)
            strength = torch.where(better, s2, strength)
        return flow, strength, passes

    def neighbour_median(self, flow: torch.Tensor, least: int = 1) -> torch.Tensor:
        """``(T, 2)`` median of each tile's measured 8 neighbours' flow ``(T, 2)``; NaN with fewer than ``least``."""
        return torch.stack([ring_median(flow[:, c].reshape(self.grid), least).reshape(-1) for c in range(2)], dim=-1)

    def consistency(self, flow: torch.Tensor, strength: torch.Tensor):
        """Tiles more than ``outlier`` px from their 8 neighbours' median flow (or unmeasured, with measured
        neighbours) are refined again from that median; the new answer is kept where it is stronger."""
        median = self.neighbour_median(flow)
        suspect = torch.isfinite(median).all(dim=1) & ~((flow - median).norm(dim=1) <= self.config.outlier)
        if not bool(suspect.any()):
            return flow, strength, 0.0
        second, s2, passes = self.refine(torch.where(suspect[:, None], median, torch.full_like(median, float("nan"))))
        better = suspect & torch.isfinite(second).all(dim=1) & ~(s2 <= strength)
        return torch.where(better[:, None], second, flow), torch.where(better, s2, strength), passes

    def _start(self, init) -> torch.Tensor:
        """``init`` (None, (x, y) or ``(tiles_y, tiles_x, 2)``) as a start ``(T, 2)``; NaN rows start at 0."""
        tiles = self.tp.tiles
        if init is None:
            return torch.zeros((tiles, 2), device=self.device)
        start = torch.as_tensor(np.asarray(init, dtype=np.float32) if not isinstance(init, torch.Tensor) else init,
                                dtype=torch.float32, device=self.device)
        if tuple(start.shape) == (2,):
            start = start.expand(tiles, 2)
        elif tuple(start.shape) == (*self.grid, 2):
            start = start.reshape(tiles, 2)
        else:
            raise ValueError(f"init: expected (x, y) or shape {(*self.grid, 2)} (tiles_y, tiles_x, 2), "
                             f"got shape {tuple(start.shape)}")
        return torch.nan_to_num(start, nan=0.0).clone()

    def starts(self, a: torch.Tensor, b: torch.Tensor, start: torch.Tensor):
        """Refined from ``start (T, 2)`` and, where the coarse levels' flow of frames ``a``, ``b`` (cams, H, W)
        differs from that answer by more than ``outlier``, from the coarse flow too; the stronger answer is
        kept: ``(flow, strength, passes)`` (the coarse levels' tiles counted at their size)."""
        flow, strength, passes = self.refine(start)
        if self.coarse is None:
            return flow, strength, passes
        size = (self.coarse.tp.height, self.coarse.tp.width)
        result = self.coarse.estimate(bin_frames(a[:1], size), bin_frames(b[:1], size),
                                      init=start.reshape(*self.grid, 2)[1::2, 1::2] / 2)  # init at the coarse grid
        passes += result.tile_passes * self.coarse.tp.tiles / self.tp.tiles
        second = scaled_start(result.flow, self.grid)
        differs = torch.isfinite(second).all(dim=1) & ~((second - flow).norm(dim=1) <= self.config.outlier)
        if bool(differs.any()):
            f2, s2, more = self.refine(torch.where(differs[:, None], second, torch.full_like(second, float("nan"))))
            passes += more
            better = differs & torch.isfinite(f2).all(dim=1) & ~(s2 <= strength)
            flow, strength = torch.where(better[:, None], f2, flow), torch.where(better, s2, strength)
        return flow, strength, passes

    def one_way(self, frame_t, frame_t1, start: torch.Tensor, maps=None):
        """``(flow, strength, passes)`` ``(T, 2)``, ``(T,)`` from ``frame_t`` to ``frame_t1`` from ``start``
        (``maps``: several cameras' disparity maps (d_t, d_t1))."""
        if self.align is not None:
            self.align.set_maps(*maps)
        self.load(frame_t, frame_t1)
        flow, strength, passes = self.starts(self.tp.staging[: self.cams], self.tp.staging[self.cams :], start)
        if self.config.search:
            flow, strength, more = self.search(start, flow, strength)
            passes += more
        flow, strength, more = self.consistency(flow, strength)
        passes += more
        # still apart from well-measured neighbours: a false peak, not a motion edge (one tuning scene, seed 7,
        # 320x240, camera 0: gross 5.1 -> 1.4 % sideways, 9.9 -> 2.8 % forward; coverage 86 -> 82, 85 -> 78 %)
        median = self.neighbour_median(flow, least=OUTLIER_SUPPORT)
        drop = torch.isfinite(median).all(dim=1) & ((flow - median).norm(dim=1) > self.config.outlier)
        # a rival peak nearly as strong: the texture matches elsewhere too (3 tuning scenes, seeds 500/600/700,
        # camera 0, the 5 motions of bench flow: mean gross 3.4 -> 2.4 %, coverage -1 point)
        measured = torch.isfinite(flow).all(dim=1) & ~drop
        _, _, rival = self._measure(flow, measured, rival=True)
        passes += float(measured.float().mean())
        drop |= measured & (rival > self.config.unique)
        return (torch.where(drop[:, None], torch.full_like(flow, float("nan")), flow),
                torch.where(drop, torch.zeros_like(strength), strength), passes)

    def disagree(self, flow: torch.Tensor, back: torch.Tensor) -> torch.Tensor:
        """``(T,)`` bool: measured tiles whose ``flow (T, 2)`` and the backward flow ``back (T, 2)`` (frame t+1
        to t) of the tile nearest where the flow lands do not sum to within ``outlier`` px (an unmeasured
        ``back``: no evidence, not flagged)."""
        centre = self.centres[:, 0] + torch.nan_to_num(flow, nan=0.0)
        iy = torch.round((centre[:, 1] - 4.0) / 8.0).clamp(0, self.grid[0] - 1).long()
        ix = torch.round((centre[:, 0] - 4.0) / 8.0).clamp(0, self.grid[1] - 1).long()
        there = back[iy * self.grid[1] + ix]
        measured = torch.isfinite(flow).all(dim=1) & torch.isfinite(there).all(dim=1)
        return measured & ~((flow + there).norm(dim=1) <= self.config.outlier)

    def estimate(self, frame_t, frame_t1, init=None, disparity=None) -> FlowResult:
        """Flow from ``frame_t`` to ``frame_t1`` (each ``(cams, height, width)`` or ``(height, width)``, torch or
        NumPy, any real dtype). ``init``: a first guess, (x, y) px or ``(tiles_y, tiles_x, 2)`` (e.g. the last
        pair's flow of a sequence; NaN rows start at 0); default 0. ``disparity``: several cameras' disparity
        maps ``(d_t, d_t1)`` of both frames, each ``(tiles_y, tiles_x)`` (default: the engine's)."""
        maps = None
        if self.align is not None:
            maps = disparity if disparity is not None else [self.engine.run(f).disparity for f in (frame_t, frame_t1)]
            if len(maps) != 2 or any(tuple(np.shape(m)) != self.grid for m in maps):
                raise ValueError(f"disparity: expected two maps of shape {self.grid} (d_t, d_t1), "
                                 f"got {[tuple(np.shape(m)) for m in maps]}")
            maps = [torch.as_tensor(np.asarray(m, dtype=np.float32)) if not isinstance(m, torch.Tensor)
                    else m.float() for m in maps]
        elif disparity is not None:
            raise ValueError("disparity: expected None for one camera, got maps")
        start = self._start(init)
        flow, strength, passes = self.one_way(frame_t, frame_t1, start, maps)
        if self.config.backward:
            back, _, more = self.one_way(frame_t1, frame_t, -start, None if maps is None else maps[::-1])
            passes += more
            drop = self.disagree(flow, back)
            flow = torch.where(drop[:, None], torch.full_like(flow, float("nan")), flow)
            strength = torch.where(drop, torch.zeros_like(strength), strength)
        valid = torch.isfinite(flow).all(dim=1)
        return FlowResult(flow.reshape(*self.grid, 2), strength.reshape(self.grid), valid.reshape(self.grid), passes)


def estimate_flow(frame_t, frame_t1, *, cfa: str | None = "GRBG", init=None, config: FlowConfig = FlowConfig(),
                  rig: Rig | None = None, device: str | None = None, backend: str | None = None) -> FlowResult:
    """Per-tile motion vectors from ``frame_t`` to ``frame_t1``: ``(height, width)`` frames of one camera, or
    ``(cams, height, width)`` of a rig's cameras (their flow combined per tile, aligned by ``rig``'s disparity:
    default the ideal quad). One-shot: build a ``FlowEstimator`` to measure many pairs of one size."""
    a = _frames("frame_t", frame_t)
    estimator = FlowEstimator(a.shape[1], a.shape[2], cams=a.shape[0], cfa=cfa, config=config, rig=rig,
                              device=device, backend=backend)
    return estimator.estimate(a, frame_t1, init=init)
