"""A rendered suite of image pairs that fail the way real photographs do (``tpnet bench rendered_pairs``).

Each case isolates one cause the real-pair bench points at (``docs/results.md``), on the same rendered layout of
objects unless the cause is the layout itself; "clean" is the reference and "real-like" combines the camera
causes. The pairs are written in the ``realdata`` layout (``tpnet_gpu.scenes.image_pairs.write_pair``) and scored
by the real-pair bench's code, so a row here reads like a row of ``tpnet bench real``.

| case | what it reproduces |
|---|---|
| clean | photographs as textures, ideal cameras, a little read noise |
| exposure | the right camera 25 % darker with another tone curve |
| noise-jpeg | photon and read noise, JPEG quality 80 |
| vertical | the right image 0.6 px lower (rectification error) |
| blur | the right camera blurrier (sigma +1 px) |
| occlusion | near boards far in front of the background: wide half-occluded strips |
| periodic | line patterns whose period is shorter than the disparity range |
| thin | sticks 3-6 px wide in front of the background |
| low-texture | faint texture (contrast 2 %) |
| real-like | exposure, tone, vertical, blur, vignetting, noise and JPEG together |
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from tpnet_gpu.io import rigfile
from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes import textures as tx
from tpnet_gpu.scenes.image_pairs import Impairments, render_pair, write_pair
from tpnet_gpu.scenes.objects import Scene, Sky, plane

SIZE = (448, 368)  # width, height: the size of the real pairs (Middlebury 2003 quarter size)
MAX_DISPARITY = 64.0  # px searched; the scenes' disparities lie in 6..60
LIGHT_NOISE = Impairments(read_noise=0.5)
CASES = {
    "clean": LIGHT_NOISE,
    "exposure": replace(LIGHT_NOISE, gain=0.75, gamma=1.25),
    "noise-jpeg": Impairments(read_noise=2.0, full_well=3000.0, jpeg_quality=80),
    "vertical": replace(LIGHT_NOISE, vertical_px=0.6),
    "blur": replace(LIGHT_NOISE, blur_px=1.0),
    "occlusion": LIGHT_NOISE,
    "periodic": LIGHT_NOISE,
    "thin": LIGHT_NOISE,
    "low-texture": LIGHT_NOISE,
    "real-like": Impairments(gain=0.85, gamma=1.1, vertical_px=0.3, blur_px=0.5, vignetting=0.3, read_noise=1.5,
                             full_well=4000.0, jpeg_quality=90),
}


def pair_rig(width: int = SIZE[0], height: int = SIZE[1]) -> Rig:
    """The shipped binocular rig cut to ``width`` x ``height`` (its focal length and baseline kept)."""
    return replace(rigfile.load("binocular"), width=width, height=height, _cache={})


def _photo(rng):
    return tx.photo_texture(str(rng.choice(tx.PHOTOS)))


def _at_disparity(rig: Rig, d: float) -> float:
    return float(rig.distance(d))


def case_scene(case: str, rig: Rig, seed: int) -> Scene:
    """The scene of ``case`` (a key of ``CASES``), deterministic for ``seed``."""
    if case not in CASES:
        raise ValueError(f"case: expected one of {sorted(CASES)}, got {case!r}")
    rng = np.random.default_rng(seed)
    w, h = rig.width, rig.height
    at = lambda fx, fy: np.array([fx * w, fy * h])  # noqa: E731
    texture = {"periodic": lambda: tx.lines_texture(rng, 512),
               "low-texture": lambda: tx.noise_texture(rng, 512, contrast=0.02)}.get(case, lambda: _photo(rng))
    items = [plane(rig, _at_disparity(rig, 8.0), texture(), centre_px=at(0.5, 0.5), size_px=(4 * w, 4 * h),
                   tilt_deg=-25.0, name="background")]
    if case == "thin":
        for i in range(7):
            items.append(plane(rig, _at_disparity(rig, rng.uniform(25, 55)), _photo(rng),
                               centre_px=at(0.1 + 0.12 * i, rng.uniform(0.4, 0.6)),
                               size_px=(rng.uniform(3, 6), rng.uniform(0.4, 0.8) * h), name=f"stick {i}"))
        return Scene(items, Sky(), name=case)
    near = (40.0, 60.0) if case == "occlusion" else (12.0, 40.0)
    for i in range(5):
        slanted = i % 2 == 1
        items.append(plane(rig, _at_disparity(rig, rng.uniform(*near)), texture(),
                           centre_px=at(rng.uniform(0.15, 0.85), rng.uniform(0.2, 0.8)),
                           size_px=(rng.uniform(0.12, 0.3) * w, rng.uniform(0.15, 0.4) * h),
                           tilt_deg=rng.uniform(-40, 40) if slanted else 0.0,
                           pan_deg=rng.uniform(-50, 50) if slanted else 0.0,
                           fit_texture=case != "periodic", gain=rng.uniform(0.6, 1.2), name=f"object {i}"))
    return Scene(items, Sky(), name=case)


def write_suite(folder, *, cases=tuple(CASES), size=SIZE, seed: int = 0, supersample: int = 2,
                gt_step: float | None = None) -> list[Path]:
    """Render ``cases`` into ``folder/CASE`` (the ``realdata`` layout); the objects' layout is the same for every
    camera case (one ``seed``). ``gt_step``: store the GT rounded to this step (px), as the real pairs' GT is (1/8
    to 1 px), to see what that rounding does to the scores; None: exact (to 1/64 px). Returns the pair folders."""
    if gt_step is not None and not 1 / 64 <= gt_step <= 4:
        raise ValueError(f"gt_step: expected 1/64 .. 4 px or None, got {gt_step}")
    rig = pair_rig(*size)
    out = []
    for case in cases:
        scene = case_scene(case, rig, seed)
        pair = render_pair(scene, rig, CASES[case], supersample=supersample, seed=seed)
        if gt_step is not None:
            pair = replace(pair, disparity=np.round(pair.disparity / gt_step) * gt_step)
        step = "" if gt_step is None else f", GT rounded to {gt_step:g} px"
        out.append(write_pair(pair, Path(folder) / case, max_disparity=MAX_DISPARITY,
                              source=f"tpnet bench rendered_pairs: case {case}, seed {seed}, {size[0]}x{size[1]}{step}"))
    return out
