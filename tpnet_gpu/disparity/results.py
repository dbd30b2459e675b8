"""What the disparity engine (engine.py) gives per frame, and the first stage's measurement its refinement reuses."""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class DisparityResult:
    """One frame's disparities, torch on the engine's device, ``(tiles_y, tiles_x)`` each.

    Attributes:
        disparity: px. Where refinement trusted no measurement: the first stage's answer if it was clear
            (margin >= ``EngineConfig.verify_margin``), the tile's windows held finite pixels and it agrees with the measured
            neighbours (``grid.fill``; strength 0 there), else NaN.
        strength: the final measurement's correlation strength (0 where none: such tiles have confidence 0).
        confidence: ``strength``, scaled by ``engine.TWO_DEPTH_WEIGHT`` on ``two_depth`` tiles (higher = surer).
        two_depth: bool, the tile's window straddles two depths (its neighbours' disparities span more than
            ``grid.TWO_DEPTH_SPREAD``): its disparity is one of them or a blend, do not trust it as a surface.
        search: the first stage's answer (before refinement), px.
        margin: the first stage's aggregated-cost margin to the best choice > 1 px away (larger = surer).
        tile_passes: tiles x cameras processed, in full-resolution passes.
        motion: the rig's forward step k (1/px, ``disparity.follow``) measured from the frame before (0 on a
            searched frame): the next followed frame starts from these answers carried by it.
        view: the frame's first camera's 8x8 means (``follow.view``): the next frame is searched in full unless it
            continues this one (``follow.continues``).
        followed: the first stage followed the frame before (False: it searched the whole range - a first frame,
            a refresh, a cut, or no ``previous``).
    """

    disparity: torch.Tensor
    strength: torch.Tensor
    confidence: torch.Tensor
    two_depth: torch.Tensor
    search: torch.Tensor
    margin: torch.Tensor
    tile_passes: float
    motion: float = 0.0
    view: torch.Tensor | None = None
    followed: bool = False


@dataclass
class FirstMeasure:
    """Step (2)'s measurement (engine.py) of every tile at its start, ``(tiles_y, tiles_x)`` each (buffers of the engine, made
    once, valid until the next frame): ``target`` the start, ``residual`` and ``strength`` as the measurer gives
    them (NaN / 0 where none), ``finite`` the tile's windows read finite pixels."""

    target: torch.Tensor
    residual: torch.Tensor
    strength: torch.Tensor
    finite: torch.Tensor
