"""Render raw Bayer frames of a scene for every camera of a rig, with exact ground truth.

Per camera: every pixel is integrated over ``supersample`` x ``supersample`` sub-pixel rays cast through that
camera's model (distortion, principal point, extrinsics; ``Rig.pixel_rays``) from its lens to the scene (exact
ray/plane intersections), then optics (lateral chromatic aberration as a radial per-colour magnification,
a Gaussian blur growing toward the field edge), the Bayer mosaic, photon (Poisson) and read noise, and
quantisation. Ground truth comes from the virtual centre camera: per-pixel disparity, and per tile the
disparity at the tile centre, the depth spread over its 16x16 window, a confidence and the surfaces the window
sees (:func:`window_surfaces`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.camera import Rig, grid_centres
from tpnet_gpu.scenes.objects import Scene

ROWS_PER_CHUNK = 64
BLUR_LEVELS = 4
SURFACES = 4  # surfaces kept per tile window (Rendered.tile_surfaces), the largest first
SURFACE_SHARE, SURFACE_LOW, SURFACE_HIGH = 0, 1, 2  # the last axis of Rendered.tile_surfaces
_OFF_IMAGE = np.iinfo(np.int32).min  # object index padding the windows that fall off the image
LUMA = np.array([0.2126, 0.7152, 0.0722])  # linear RGB -> luminance


@dataclass(frozen=True)
class Optics:
    """Lens model. ``sigma_*``: Gaussian PSF sigma (px) on axis and at the image corner (quadratic in the
    radius between); ``lateral_ca``: radial displacement (px) of red (outward) and blue (inward) at the corner,
    growing linearly with the radius (green is the reference)."""

    sigma_centre: float = 0.5
    sigma_edge: float = 0.9
    lateral_ca: float = 0.6

    def sigma(self, radius_fraction):
        return self.sigma_centre + (self.sigma_edge - self.sigma_centre) * np.asarray(radius_fraction) ** 2

    def psfs(self, rig: Rig) -> np.ndarray:
        """The same lens as PSFs on the aberration-kernel grid, ``(cams, rows, cols, 3, s, s)`` (R, B, G), for
        ``tpnet_gpu.aberration.deconvolution_kernels``."""
        from tpnet_gpu.aberration import field_psfs  # noqa: PLC0415

        return field_psfs(rig.height, rig.width, rig.cams, sigma_centre=self.sigma_centre,
                          sigma_edge=self.sigma_edge, lateral_ca=self.lateral_ca)


@dataclass(frozen=True)
class Sensor:
    """Sensor model: ``bits`` of output, ``black_level`` (DN), reflectance 1 maps to ``exposure`` of the range
    above black; ``full_well`` electrons at the white level (photon noise); ``read_noise`` (DN, Gaussian);
    ``cfa``: the Bayer pattern, or None for a mono sensor (each pixel the luminance of R, G, B)."""

    bits: int = 12
    black_level: int = 64
    exposure: float = 0.7
    full_well: float = 12000.0
    read_noise: float = 2.0
    cfa: str | None = tables.DEFAULT_CFA

    @property
    def white_level(self) -> int:
        return 2**self.bits - 1


@dataclass(frozen=True)
class Rendered:
    """A rendered scene.

    Attributes:
        raws: ``(cams, H, W)`` uint16 raw mosaics (``sensor.cfa``; mono: luminance), black level included.
        disparity: ``(H, W)`` float32 ground-truth disparity of every virtual-camera pixel (0 for the sky).
        objects: ``(H, W)`` int16 index of the object each virtual-camera pixel sees (-1 sky).
        tile_disparity: ``(tiles_y, tiles_x)`` disparity at each tile centre (8 tx + 4, 8 ty + 4).
        tile_spread: ``(tiles_y, tiles_x)`` max - min ground-truth disparity over the tile's 16x16 window.
        tile_confidence: ``(tiles_y, tiles_x)`` in [0, 1]: low where the window has no texture or mixes objects.
        tile_surfaces: ``(tiles_y, tiles_x, SURFACES, 3)`` float32, the surfaces (objects, the sky included)
            the tile's 16x16 window sees, largest first, NaN-padded: (share of the window's in-image pixels,
            min, max disparity of its pixels there); see :func:`window_surfaces`.
        sensor, rig: what made it.
    """

    raws: np.ndarray
    disparity: np.ndarray
    objects: np.ndarray
    tile_disparity: np.ndarray
    tile_spread: np.ndarray
    tile_confidence: np.ndarray
    tile_surfaces: np.ndarray
    sensor: Sensor
    rig: Rig

    def ground_truth(self) -> dict:
        """The ground truth as a dict of arrays (for scene folders)."""
        return {"disparity": self.disparity, "objects": self.objects, "tile_disparity": self.tile_disparity,
                "tile_spread": self.tile_spread, "tile_confidence": self.tile_confidence,
                "tile_surfaces": self.tile_surfaces}


def _radiance(scene: Scene, rig: Rig, cam: int, supersample: int) -> np.ndarray:
    """Noise-free reflectance planes ``(3, H, W)`` R G B of camera ``cam``, box-integrated over sub-pixels."""
    height, width = rig.height, rig.width
    out = np.zeros((3, height, width), dtype=np.float32)
    sub = (np.arange(supersample) + 0.5) / supersample
    origin = rig.lens_positions()[cam]
    for y0 in range(0, height, ROWS_PER_CHUNK):
        rows = min(ROWS_PER_CHUNK, height - y0)
        ys = (y0 + np.arange(rows)[:, None] + sub[None, :]).reshape(-1)
        xs = (np.arange(width)[:, None] + sub[None, :]).reshape(-1)
        px = np.stack(np.meshgrid(xs, ys, indexing="xy"), axis=-1).reshape(-1, 2)
        dirs = rig.pixel_rays(cam, px)
        rgb, _, _ = scene.trace(np.broadcast_to(origin, dirs.shape), dirs)
        rgb = rgb.reshape(rows, supersample, width, supersample, 3).mean(axis=(1, 3))
        out[:, y0 : y0 + rows] = np.moveaxis(rgb, -1, 0)
    return out


def apply_optics(planes: np.ndarray, optics: Optics, principal: np.ndarray) -> np.ndarray:
    """Lateral CA (radial magnification of R outward, B inward) then the field-dependent blur, ``(3, H, W)``."""
    from scipy import ndimage  # noqa: PLC0415 - on use: reading a scene folder needs no renderer (start-up)

    _, height, width = planes.shape
    y, x = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    dx, dy = x - principal[0], y - principal[1]
    r_max = np.hypot(width / 2.0, height / 2.0)
    radius = np.hypot(dx, dy) / r_max
    sigma = optics.sigma(radius)
    levels = np.linspace(sigma.min(), sigma.max(), BLUR_LEVELS) if sigma.max() > sigma.min() else sigma.max()[None]
    out = np.empty_like(planes)
    for colour, sign in enumerate((1.0, 0.0, -1.0)):  # R out, G reference, B in
        plane = planes[colour].astype(np.float64)
        if sign and optics.lateral_ca:
            shrink = 1.0 - sign * optics.lateral_ca / r_max  # observed(P) = scene(pp + (P - pp) shrink)
            coords = [principal[1] + dy * shrink - 0.5, principal[0] + dx * shrink - 0.5]
            plane = ndimage.map_coordinates(plane, coords, order=3, mode="reflect")
        blurred = [ndimage.gaussian_filter(plane, s, mode="reflect") if s > 0 else plane for s in levels]
        if len(levels) == 1:
            out[colour] = blurred[0]
            continue
        pos = np.clip((sigma - levels[0]) / (levels[1] - levels[0]), 0, len(levels) - 1 - 1e-9)
        low = np.floor(pos).astype(int)
        frac = pos - low
        stack = np.stack(blurred)
        out[colour] = (np.take_along_axis(stack, low[None], 0)[0] * (1 - frac)
                       + np.take_along_axis(stack, low[None] + 1, 0)[0] * frac)
    return out


def expose(planes: np.ndarray, sensor: Sensor, rng: np.random.Generator | None) -> np.ndarray:
    """Mosaic ``(3, H, W)`` R G B reflectance into the CFA (a mono sensor: their luminance), add photon and read
    noise (if ``rng``), quantise."""
    _, height, width = planes.shape
    if sensor.cfa is None:
        mosaic = np.tensordot(LUMA, planes, axes=1).astype(np.float64)
    else:
        colour = tables.cfa_colour_index(sensor.cfa, height, width)  # 0 R, 1 B, 2 G
        rgb_index = np.array([0, 2, 1])[colour]  # project colour order -> R G B plane index
        mosaic = np.take_along_axis(planes, rgb_index[None], axis=0)[0].astype(np.float64)
    span = sensor.white_level - sensor.black_level
    signal = np.clip(mosaic, 0, None) * sensor.exposure * span  # DN above black
    if rng is not None:
        electrons_per_dn = sensor.full_well / span
        signal = rng.poisson(signal * electrons_per_dn) / electrons_per_dn
        signal = signal + rng.normal(0.0, sensor.read_noise, size=signal.shape)
    return np.clip(np.round(signal + sensor.black_level), 0, sensor.white_level).astype(np.uint16)


def _ground_truth(scene: Scene, rig: Rig):
    """Virtual-camera disparity ``(H, W)``, object index map, and the noise-free luminance ``(H, W)``."""
    height, width = rig.height, rig.width
    y, x = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    dirs = rig.virtual_rays(np.stack([x, y], axis=-1).reshape(-1, 2))
    rgb, depth, index = scene.trace(np.zeros_like(dirs), dirs)
    with np.errstate(divide="ignore"):
        disparity = rig.focal_mm * rig.baseline_mm / (depth * rig.pixel_size_mm)
    return (disparity.reshape(height, width).astype(np.float32), index.reshape(height, width).astype(np.int16),
            (rgb @ LUMA).reshape(height, width))


def tile_ground_truth(scene: Scene, rig: Rig, disparity, objects, luminance, *, texture_floor: float = 0.02):
    """Per tile: disparity at the centre ray, spread and confidence over the 16x16 window (clipped to the
    image). Confidence = min(1, luminance std / ``texture_floor``), x 0.1 where the window sees > 1 object."""
    tiles_y, tiles_x = rig.height // 8, rig.width // 8
    centres = grid_centres(tiles_y, tiles_x).reshape(-1, 2)
    _, depth, _ = scene.trace(np.zeros((len(centres), 3)), rig.virtual_rays(centres))
    with np.errstate(divide="ignore"):
        tile_d = (rig.focal_mm * rig.baseline_mm / (depth * rig.pixel_size_mm)).reshape(tiles_y, tiles_x)
    pad = ((4, 4), (4, 4))
    d = np.pad(disparity, pad, mode="edge")
    o = np.pad(objects, pad, mode="edge")
    lum = np.pad(luminance, pad, mode="edge")
    windows = lambda a: np.lib.stride_tricks.sliding_window_view(a, (16, 16))[::8, ::8][:tiles_y, :tiles_x]  # noqa: E731
    wd, wo, wl = windows(d), windows(o), windows(lum)
    spread = wd.max(axis=(-2, -1)) - wd.min(axis=(-2, -1))
    mixed = wo.max(axis=(-2, -1)) != wo.min(axis=(-2, -1))
    confidence = np.minimum(1.0, wl.std(axis=(-2, -1)) / texture_floor) * np.where(mixed, 0.1, 1.0)
    return tile_d.astype(np.float32), spread.astype(np.float32), confidence.astype(np.float32)


def _tile_windows(image: np.ndarray, fill) -> np.ndarray:
    """``(tiles_y, tiles_x, 16, 16)`` view of every tile's window (starting at (8 tx - 4, 8 ty - 4)) of
    ``image`` padded by 4 pixels of ``fill``."""
    tiles_y, tiles_x = image.shape[0] // 8, image.shape[1] // 8
    padded = np.pad(image, 4, mode="constant", constant_values=fill)
    return np.lib.stride_tricks.sliding_window_view(padded, (16, 16))[::8, ::8][:tiles_y, :tiles_x]


def window_surfaces(disparity: np.ndarray, objects: np.ndarray, *, surfaces: int = SURFACES) -> np.ndarray:
    """The surfaces each tile's 16x16 window sees, ``(tiles_y, tiles_x, surfaces, 3)`` float32.

    A surface is one scene object (one plane, slanted or not; the sky is one more, index -1) as the per-pixel
    ``objects`` map of the virtual camera shows it. Per tile and surface: its share of the window's pixels that
    lie inside the image, and the min and max ``disparity`` of those of its pixels (a slanted plane spans a
    range; a plane seen in two pieces spans both). The ``surfaces`` largest, by pixel count (ties: lower
    object index first), NaN rows after the last one the window sees."""
    disparity = np.asarray(disparity, dtype=np.float32)
    objects = np.asarray(objects, dtype=np.int32)
    wo = _tile_windows(objects, _OFF_IMAGE)
    wd = _tile_windows(disparity, np.nan)
    inside = (wo != _OFF_IMAGE).sum(axis=(-2, -1))
    ids = np.unique(objects)
    counts = np.zeros((len(ids), *inside.shape), dtype=np.int32)
    low = np.full(counts.shape, np.nan, dtype=np.float32)
    high = np.full(counts.shape, np.nan, dtype=np.float32)
    for i, obj in enumerate(ids):
        seen = wo == obj
        counts[i] = seen.sum(axis=(-2, -1))
        low[i] = np.where(seen, wd, np.inf).min(axis=(-2, -1))
        high[i] = np.where(seen, wd, -np.inf).max(axis=(-2, -1))
    order = np.argsort(-counts, axis=0, kind="stable")[:surfaces]
    pick = lambda a: np.take_along_axis(a, order, axis=0)  # noqa: E731
    count = pick(counts)
    rows = np.stack([count / inside, pick(low), pick(high)], axis=-1).astype(np.float32)
    rows[count == 0] = np.nan
    out = np.full((*inside.shape, surfaces, 3), np.nan, dtype=np.float32)
    out[:, :, : len(order)] = np.moveaxis(rows, 0, 2)
    return out


def render(scene: Scene, rig: Rig = Rig(), *, optics: Optics = Optics(), sensor: Sensor = Sensor(),
           supersample: int = 2, seed: int = 0, noise: bool = True, progress=None) -> Rendered:
    """Render ``scene`` for every camera of ``rig``; deterministic for ``seed``. ``progress``: optional
    callable taking a message (one call per camera)."""
    if rig.width % 8 or rig.height % 8 or min(rig.width, rig.height) < 16:
        raise ValueError(f"rig: expected a sensor size in multiples of 8, at least 16x16, got {rig.width}x{rig.height}")
    if supersample < 1:
        raise ValueError(f"supersample: expected >= 1, got {supersample}")
    raws = np.empty((rig.cams, rig.height, rig.width), dtype=np.uint16)
    principal = rig.principal()
    for cam in range(rig.cams):
        if progress is not None:
            progress(f"camera {cam + 1}/{rig.cams}")
        planes = apply_optics(_radiance(scene, rig, cam, supersample), optics, principal[cam])
        rng = np.random.default_rng([seed, cam]) if noise else None
        raws[cam] = expose(planes, sensor, rng)
    disparity, objects, luminance = _ground_truth(scene, rig)
    tile_d, spread, confidence = tile_ground_truth(scene, rig, disparity, objects, luminance)
    surfaces = window_surfaces(disparity, objects)
    return Rendered(raws, disparity, objects, tile_d, spread, confidence, surfaces, sensor, rig)
