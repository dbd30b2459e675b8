"""Rendered scenes on disk: the project's scene folder (one DNG per camera, ground truth as NPZ + TIFF, and
``scene.json`` with the rig, optics and sensor), written and read through ``tpnet_gpu.io.rawio``."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpnet_gpu.io import rawio
from tpnet_gpu.camera import Rig
from tpnet_gpu.io.images import colour_ramp, raw_preview, save_png
from tpnet_gpu.scenes.render import Rendered, window_surfaces


def save(rendered: Rendered, folder, *, name: str = "scene", optics=None, previews: bool = True) -> Path:
    """Write ``rendered`` as a scene folder (+ ``preview_cam0.png`` and ``disparity.png`` if ``previews``)."""
    sensor = rendered.sensor
    camera = {"rig": rendered.rig.to_json(), "sensor": dataclasses.asdict(sensor), "scene": name,
              "optics": None if optics is None else dataclasses.asdict(optics)}
    folder = rawio.write_scene(folder, rendered.raws, sensor.cfa, black_level=sensor.black_level,
                               white_level=sensor.white_level, ground_truth=rendered.ground_truth(),
                               camera=camera, bits=16)
    if previews:
        save_png(Path(folder) / "preview_cam0.png",
                 raw_preview(rendered.raws[0], sensor.cfa, sensor.black_level, sensor.white_level))
        save_png(Path(folder) / "disparity.png", colour_ramp(rendered.disparity, 0.0))
    return Path(folder)


@dataclass(frozen=True, eq=False)
class LoadedScene:
    """A scene folder ready for the tile processor: ``frames (cams, H, W)`` float32 black-subtracted,
    ``cfa``, the ``rig`` (ideal quad of the frame size if the folder has none), ``ground_truth`` arrays."""

    frames: np.ndarray
    cfa: str
    rig: Rig
    ground_truth: dict
    folder: Path


def load(folder) -> LoadedScene:
    """Read a scene folder (DNGs through rawpy) into float frames and its rig. A folder written before
    ``tile_surfaces`` existed gets them from its per-pixel ``disparity`` and ``objects``."""
    scene = rawio.read_scene(folder)
    frames = rawio.stack_normalised(scene.frames)
    rig_json = (scene.camera or {}).get("rig")
    rig = Rig.from_json(rig_json) if rig_json else Rig(width=frames.shape[2], height=frames.shape[1])
    if (rig.height, rig.width) != frames.shape[1:] or rig.cams != frames.shape[0]:
        raise rawio.RawFormatError(
            f"{folder}: scene.json describes {rig.cams} cameras of {rig.width}x{rig.height}, "
            f"the files hold {frames.shape[0]} of {frames.shape[2]}x{frames.shape[1]}"
        )
    gt = dict(scene.ground_truth)
    if "tile_surfaces" not in gt and {"disparity", "objects"} <= gt.keys():
        gt["tile_surfaces"] = window_surfaces(gt["disparity"], gt["objects"])
    return LoadedScene(frames, scene.frames[0].cfa, rig, gt, Path(folder))
