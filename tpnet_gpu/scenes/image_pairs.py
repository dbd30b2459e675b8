"""Rendered rectified image pairs that fail the way real photographs do, with exact ground truth.

A pair is what ``tpnet process LEFT.png RIGHT.png`` reads: two 8-bit grey images of a two-camera rig (camera 0
left, camera 1 right), rendered with :func:`tpnet_gpu.scenes.render.apply_optics` per camera and finished the way
an ordinary camera finishes its images (exposure, photon and read noise, sRGB-like tone curve, 8 bits, JPEG
compression optional). :class:`Impairments` holds what separates a real camera pair from an ideal one: a gain and
a tone-curve difference of the right camera, its sub-pixel vertical misalignment, an extra blur, vignetting.

The ground truth is the left view's (``left[y, x] ~ right[y, x - d]``, the convention of ``../shared/realdata``):
per left pixel centre, the disparity of the surface its ray hits, and whether the right camera sees that same
point (non-occluded). :func:`write_pair` writes the ``realdata`` layout, so ``tpnet bench real`` reads rendered
and real pairs alike.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes.objects import Scene
from tpnet_gpu.scenes.render import LUMA, Optics, _radiance, apply_optics

GT_SCALE = 64  # gt.png stores round(disparity * GT_SCALE) in 16 bits, 0 = unknown (the realdata layout)
SAME_POINT_MM = 1.0  # the right camera sees the left's point when its own ray ends within this of it (depth)


@dataclass(frozen=True)
class Impairments:
    """How the right camera and the finishing of both images depart from an ideal pair.

    ``gain``: the right camera's exposure over the left's; ``gamma``: exponent on the right's tone curve
    (1 = the same curve); ``vertical_px``: the right image's content moves down by this (rectification error);
    ``blur_px``: extra Gaussian sigma (px) of the right camera; ``vignetting``: light lost at the image corner,
    both cameras (cos^4-like, quadratic in the radius); ``read_noise``: Gaussian noise, 8-bit DN, both;
    ``full_well``: electrons at white (photon noise; 0 = none); ``jpeg_quality``: JPEG round trip of both
    images (None = none)."""

    gain: float = 1.0
    gamma: float = 1.0
    vertical_px: float = 0.0
    blur_px: float = 0.0
    vignetting: float = 0.0
    read_noise: float = 0.0
    full_well: float = 0.0
    jpeg_quality: int | None = None

    def __post_init__(self):
        for name in ("gain", "gamma"):
            if not 0.1 <= getattr(self, name) <= 10:
                raise ValueError(f"{name}: expected 0.1..10, got {getattr(self, name)}")
        for name in ("blur_px", "read_noise", "full_well"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: expected >= 0, got {getattr(self, name)}")
        if not abs(self.vertical_px) <= 4:
            raise ValueError(f"vertical_px: expected -4..4, got {self.vertical_px}")
        if not 0 <= self.vignetting < 1:
            raise ValueError(f"vignetting: expected 0 <= v < 1, got {self.vignetting}")
        if self.jpeg_quality is not None and not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality: expected 1..100 or None, got {self.jpeg_quality}")


@dataclass(frozen=True)
class ImagePair:
    """``left``, ``right``: ``(H, W)`` uint8 images; ``disparity``: ``(H, W)`` float64 left-view GT, px (NaN for
    the sky); ``nonocc``: ``(H, W)`` bool, the right camera sees the left pixel's point inside its image."""

    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    nonocc: np.ndarray


def _check_rig(rig: Rig):
    r = rig.offsets_array()
    if rig.cams != 2 or not np.allclose(r[1] - r[0], (1.0, 0.0)) or not rig.is_ideal():
        raise ValueError("rig: expected an ideal rectified pair, camera 1 one baseline right of camera 0 "
                         f"(the shipped binocular rig), got offsets {r.tolist()}")


def _finish(planes: np.ndarray, exposure: float, gamma: float, vignetting: float, impair: Impairments,
            rng: np.random.Generator | None) -> np.ndarray:
    """Linear RGB ``(3, H, W)`` -> 8-bit grey ``(H, W)``: luma, vignetting, exposure, noise, tone curve."""
    _, height, width = planes.shape
    y, x = np.mgrid[0:height, 0:width] + 0.5
    radius2 = ((x - width / 2) ** 2 + (y - height / 2) ** 2) / ((width / 2) ** 2 + (height / 2) ** 2)
    signal = np.tensordot(LUMA, planes, axes=1) * exposure * (1.0 - vignetting * radius2)
    signal = np.clip(signal, 0.0, 1.0)
    if rng is not None and impair.full_well > 0:
        signal = rng.poisson(signal * impair.full_well) / impair.full_well
    tone = np.clip(signal, 0.0, 1.0) ** (gamma / 2.2)  # a plain power law stands for the camera's curve
    dn = tone * 255.0
    if rng is not None and impair.read_noise > 0:
        dn = dn + rng.normal(0.0, impair.read_noise, size=dn.shape)
    return np.clip(np.round(dn), 0, 255).astype(np.uint8)


def _jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    import io  # noqa: PLC0415

    from PIL import Image  # noqa: PLC0415

    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="JPEG", quality=quality)
    buffer.seek(0)
    with Image.open(buffer) as im:
        return np.asarray(im.convert("L")).copy()


@dataclass(frozen=True)
class PhotoFinish:
    """How ``finish_raws`` turns a mono camera's linear frame into an ordinary 8-bit image: ``gain`` (exposure
    over the render's), ``gamma`` (exponent on the sRGB-like curve x^(1/2.2); 1 = that curve), ``blur_px`` (extra
    Gaussian sigma), ``jpeg_quality`` (None = none)."""

    gain: float = 1.0
    gamma: float = 1.0
    blur_px: float = 0.0
    jpeg_quality: int | None = None

    @classmethod
    def draw(cls, rng: np.random.Generator) -> PhotoFinish:
        """A random camera of an ordinary stereo pair: gain 0.7-1.3, gamma 0.85-1.15, blur 0-0.8 px on half the
        cameras, JPEG quality 70-98 on 2 in 3 (one draw per camera)."""
        return cls(gain=float(rng.uniform(0.7, 1.3)), gamma=float(rng.uniform(0.85, 1.15)),
                   blur_px=float(rng.uniform(0.0, 0.8)) if rng.random() < 0.5 else 0.0,
                   jpeg_quality=int(rng.integers(70, 99)) if rng.random() < 2 / 3 else None)


def photo_optics(rng: np.random.Generator) -> Optics:
    """A random lens for photograph-like data: PSF sigma 0.15-0.6 px on axis, up to 0.3 px more at the corner,
    lateral colour 0-0.6 px (the renderer's default lens: 0.5, 0.9, 0.6)."""
    centre = float(rng.uniform(0.15, 0.6))
    return Optics(centre, centre + float(rng.uniform(0.0, 0.3)), float(rng.uniform(0.0, 0.6)))


def finish_raws(raws: np.ndarray, black_level: int, white_level: int, finishes) -> np.ndarray:
    """Mono raws ``(cams, H, W)`` (linear, black level included) -> ``(cams, H, W)`` uint16 holding 0..255, each
    camera finished by its ``PhotoFinish``: blur, gain, tone curve, 8 bits, JPEG - what ``tpnet process`` reads
    from a PNG or JPEG pair (gamma-encoded, 8-bit), black level 0."""
    from scipy import ndimage  # noqa: PLC0415

    out = np.empty(raws.shape, dtype=np.uint16)
    for cam, finish in enumerate(finishes):
        linear = (raws[cam].astype(np.float64) - black_level) / (white_level - black_level)
        if finish.blur_px > 0:
            linear = ndimage.gaussian_filter(linear, finish.blur_px, mode="reflect")
        tone = np.clip(linear * finish.gain, 0.0, 1.0) ** (finish.gamma / 2.2)
        image = np.round(tone * 255.0).astype(np.uint8)
        out[cam] = image if finish.jpeg_quality is None else _jpeg(image, finish.jpeg_quality)
    return out


def _left_truth(scene: Scene, rig: Rig, right_rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Left-view GT disparity ``(H, W)`` (NaN sky) and the non-occlusion mask, at the pixel centres."""
    height, width = rig.height, rig.width
    y, x = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    pixels = np.stack([x, y], axis=-1).reshape(-1, 2)
    lens = rig.lens_positions()
    _, depth, _ = scene.trace(np.broadcast_to(lens[0], (len(pixels), 3)), rig.pixel_rays(0, pixels))
    disparity = np.where(np.isfinite(depth), rig.focal_mm * rig.baseline_mm / (depth * rig.pixel_size_mm), np.nan)
    # the right camera's pixel of the same point: x - d, and the right image's content is vertical_px lower
    shift_y = right_rig.principal()[1, 1] - rig.principal()[1, 1]
    seen = np.stack([pixels[:, 0] - disparity, pixels[:, 1] + shift_y], axis=-1)
    inside = (np.isfinite(disparity) & (seen[:, 0] >= 0) & (seen[:, 0] < width) & (seen[:, 1] >= 0)
              & (seen[:, 1] < height))
    probe = np.where(inside[:, None], seen, 0.5)
    _, depth_right, _ = scene.trace(np.broadcast_to(lens[1], (len(pixels), 3)), right_rig.pixel_rays(1, probe))
    same = np.abs(np.where(inside, depth_right - np.where(inside, depth, 0.0), np.inf)) < SAME_POINT_MM  # no inf - inf
    nonocc = inside & same
    return disparity.reshape(height, width), nonocc.reshape(height, width)


def render_pair(scene: Scene, rig: Rig, impair: Impairments = Impairments(), *, optics: Optics = Optics(0.5, 0.7, 0.0),
                exposure: float = 0.8, supersample: int = 2, seed: int = 0, noise: bool = True) -> ImagePair:
    """Render ``scene`` as a left / right image pair of the ideal rectified two-camera ``rig``; deterministic
    for ``seed``. The right camera gets ``impair``'s gain, tone, vertical offset and blur."""
    from scipy import ndimage  # noqa: PLC0415

    _check_rig(rig)
    principal = rig.principal()
    right_points = principal.copy()
    right_points[1, 1] += impair.vertical_px  # a principal point lower: the image content moves down
    right_rig = replace(rig, principal_points=tuple(map(tuple, right_points)), _cache={})
    images = []
    for cam, (cam_rig, gain, gamma) in enumerate(((rig, 1.0, 1.0), (right_rig, impair.gain, impair.gamma))):
        planes = apply_optics(_radiance(scene, cam_rig, cam, supersample), optics, cam_rig.principal()[cam])
        if cam == 1 and impair.blur_px > 0:
            planes = np.stack([ndimage.gaussian_filter(p, impair.blur_px, mode="reflect") for p in planes])
        rng = np.random.default_rng([seed, cam]) if noise else None
        image = _finish(planes, exposure * gain, gamma, impair.vignetting, impair, rng)
        images.append(image if impair.jpeg_quality is None else _jpeg(image, impair.jpeg_quality))
    disparity, nonocc = _left_truth(scene, rig, right_rig)
    return ImagePair(images[0], images[1], disparity, nonocc)


def write_pair(pair: ImagePair, folder, *, max_disparity: float, source: str = "") -> Path:
    """Write ``pair`` in the ``realdata`` layout (left.png, right.png, gt.png, mask_nonocc.png, meta.json); the
    folder must not exist or be empty. Returns the folder."""
    from PIL import Image  # noqa: PLC0415

    folder = Path(folder)
    if folder.exists() and any(folder.iterdir()):
        raise FileExistsError(f"folder: expected a new or empty folder, {folder} holds files")
    if not np.nanmax(pair.disparity, initial=0.0) * GT_SCALE < 65535:
        raise ValueError(f"pair: a disparity over {65535 / GT_SCALE:.0f} px does not fit gt.png")
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(pair.left).save(folder / "left.png")
    Image.fromarray(pair.right).save(folder / "right.png")
    gt = np.where(np.isfinite(pair.disparity), np.round(pair.disparity * GT_SCALE), 0).astype(np.uint16)
    Image.fromarray(gt).save(folder / "gt.png")
    Image.fromarray(np.where(pair.nonocc, 255, 0).astype(np.uint8)).save(folder / "mask_nonocc.png")
    meta = {"gt": "gt.png", "gt_scale": GT_SCALE, "invalid": 0, "max_disparity": float(max_disparity),
            "source": source}
    (folder / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return folder
