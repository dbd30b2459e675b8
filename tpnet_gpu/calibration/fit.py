"""Field calibration of the quad's extrinsic corrections from frames (docs/calibration.md): rounds of measure
(``measure.observe``, re-correlated with the current rig) and fit (robust LMA, ``lma.fit``; or gradient descent
through the differentiable tile processor, ``gradient.fit``), until the corrections stop moving the frame edge."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from tpnet_gpu.calibration import model
from tpnet_gpu.calibration.lma import LmaSettings, Observations, fit as lma_fit
from tpnet_gpu.calibration.measure import Frame, observe
from tpnet_gpu import tables
from tpnet_gpu.camera import Rig

METHODS = ("lma", "gradient")


@dataclass(frozen=True)
class CalibrationConfig:
    """``rounds``: most measure + fit rounds; ``tolerance``: stop when a round moves the frame edge by less (px);
    ``lma``: the robust fit's settings; ``gradient_steps``: L-BFGS iterations per round of the gradient method,
    on at most ``gradient_tiles`` tiles per frame (the strongest: each iteration re-correlates them all)."""

    rounds: int = 4
    tolerance: float = 0.02
    lma: LmaSettings = LmaSettings()
    gradient_steps: int = 10
    gradient_tiles: int = 300

    def __post_init__(self):
        for name in ("rounds", "gradient_steps", "gradient_tiles"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected an int >= 1, got {value!r}")
        if not (isinstance(self.tolerance, (int, float)) and np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"tolerance: expected a finite number of pixels > 0, got {self.tolerance!r}")


@dataclass(frozen=True)
class CalibrationResult:
    """``rig``: the calibrated rig; ``extrinsics`` ``(13,)``; ``rounds``: per round ``tiles``, ``moved_px`` (frame
    edge), the fit's summary; ``seconds``: wall time."""

    rig: Rig
    extrinsics: np.ndarray
    rounds: list = field(default_factory=list)
    seconds: float = 0.0


def _frames(scenes) -> list[Frame]:
    scenes = list(scenes)
    if not scenes:
        raise ValueError("scenes: expected at least one frame, got none")
    out = []
    for i, s in enumerate(scenes):
        frame = s if isinstance(s, Frame) else Frame(np.asarray(s))
        if frame.frames.ndim != 3 or frame.frames.shape[0] != 4:
            raise ValueError(f"scenes[{i}]: expected frames of shape (4, H, W), got {frame.frames.shape}")
        out.append(frame)
    return out


def calibrate(scenes, rig: Rig, *, method: str = "lma", config: CalibrationConfig = CalibrationConfig(),
              device=None, backend=None, log=None) -> CalibrationResult:
    """Fit ``rig``'s 13 extrinsic corrections (the two gauge directions, ``model.gauge``, left as they are) to
    ``scenes``: ``Frame`` objects or ``(4, H, W)`` arrays (Bayer GRBG, black level removed) of one rig.
    ``method``: ``"lma"`` (robust Levenberg-Marquardt on measured 2-D peaks) or ``"gradient"`` (L-BFGS through
    the differentiable tile processor)."""
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    model.check_quad(rig)
    frames = _frames(scenes)
    for i, f in enumerate(frames):
        if f.frames.shape[1:] != (rig.height, rig.width):
            raise ValueError(f"scenes[{i}]: expected {rig.width}x{rig.height} frames (the rig), got "
                             f"{f.frames.shape[2]}x{f.frames.shape[1]}")
    start = time.perf_counter()
    e = np.asarray(rig.extrinsics, dtype=np.float64)
    rounds = []
    for n in range(config.rounds):
        current = model.with_extrinsics(rig, e)
        if method == "lma":
            obs = Observations.join(observe(f, current, device=device, backend=backend) for f in frames)
            e_new, summary = lma_fit(rig, e, obs, tables.QUAD_PAIRS, config.lma)
            summary["tiles"] = len(obs.disparity)
        else:
            from tpnet_gpu.calibration.gradient import fit as gradient_fit  # noqa: PLC0415 - torch autograd path

            e_new, summary = gradient_fit(frames, current, config.gradient_steps, config.gradient_tiles, device=device,
                                         backend=backend)
        moved = model.edge_misalignment(rig, e_new, e)
        e = e_new
        rounds.append({**summary, "moved_px": moved})
        if log is not None:
            log(f"round {n + 1}: {summary.get('tiles')} tiles, frame edge moved {moved:.3f} px")
        if moved < config.tolerance:
            break
    return CalibrationResult(model.with_extrinsics(rig, e), e, rounds, time.perf_counter() - start)
