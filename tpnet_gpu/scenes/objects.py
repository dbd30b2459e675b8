"""Scene objects for the renderer: textured planar patches (fronto-parallel or slanted, bounded or not) and a
sky at infinity. World coordinates as ``tpnet_gpu.camera``: millimetres, x right, y up, z toward the viewer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes.textures import sample


@dataclass
class Patch:
    """A textured plane through ``origin`` spanned by unit vectors ``u_axis``, ``v_axis`` (world mm).

    ``half_size`` (mm along u, v) bounds it to a rectangle (``elliptic``: an ellipse); infinite = unbounded.
    The texture raster ``(n, n, 3)`` maps one texel to ``texel_mm``; ``gain`` scales its reflectance.
    """

    origin: np.ndarray
    u_axis: np.ndarray
    v_axis: np.ndarray
    texture: np.ndarray
    texel_mm: float
    half_size: tuple[float, float] = (np.inf, np.inf)
    elliptic: bool = False
    gain: float = 1.0
    name: str = "patch"

    def __post_init__(self):
        self.origin = np.asarray(self.origin, dtype=np.float64)
        self.u_axis = np.asarray(self.u_axis, dtype=np.float64)
        self.v_axis = np.asarray(self.v_axis, dtype=np.float64)
        self.normal = np.cross(self.u_axis, self.v_axis)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray parameters t ``(N,)`` of the hits (inf where missed or behind) and plane coordinates u, v (mm)."""
        denom = dirs @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.origin - origins) @ self.normal) / denom
        hit = origins + t[:, None] * dirs - self.origin
        u = hit @ self.u_axis
        v = hit @ self.v_axis
        hu, hv = self.half_size
        if self.elliptic:
            inside = (u / hu) ** 2 + (v / hv) ** 2 <= 1.0
        else:
            inside = (np.abs(u) <= hu) & (np.abs(v) <= hv)
        ok = np.isfinite(t) & (t > 0) & inside
        return np.where(ok, t, np.inf), u, v

    def colour(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Reflectance ``(N, 3)`` at plane coordinates (mm); texture rows run against v (image-like) and the
        texture's centre sits at the patch origin."""
        half = self.texture.shape[0] / 2.0
        return self.gain * sample(self.texture, u / self.texel_mm + half, -v / self.texel_mm + half)


@dataclass
class Sky:
    """Near-uniform sky at infinity: a vertical gradient from ``horizon`` to ``zenith`` colour plus faint
    large-scale texture (``texture`` sampled by direction, ``contrast`` of it)."""

    horizon: tuple = (0.75, 0.8, 0.9)
    zenith: tuple = (0.35, 0.5, 0.85)
    texture: np.ndarray | None = None
    contrast: float = 0.02

    def colour(self, dirs: np.ndarray) -> np.ndarray:
        d = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        elevation = np.clip(d[:, 1], -1, 1)[:, None]
        mix = np.clip(elevation * 4.0, 0, 1)
        rgb = (1 - mix) * np.asarray(self.horizon) + mix * np.asarray(self.zenith)
        if self.texture is not None:
            n = self.texture.shape[0]
            t = sample(self.texture, d[:, 0] / -d[:, 2] * n, d[:, 1] / -d[:, 2] * n)
            rgb = rgb * (1.0 + self.contrast * (t - t.mean(axis=0)) / (t.std() + 1e-6))
        return rgb


@dataclass
class Scene:
    """Objects in front of the rig and a sky. ``trace`` finds the nearest hit of each ray."""

    objects: list = field(default_factory=list)
    sky: Sky = field(default_factory=Sky)
    name: str = "scene"

    def trace(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rays ``(N, 3)`` -> (reflectance ``(N, 3)``, depth -z of the hit in mm ``(N,)`` (inf for the sky),
        object index ``(N,)`` (-1 for the sky))."""
        n = len(dirs)
        best = np.full(n, np.inf)
        index = np.full(n, -1)
        coords = np.zeros((n, 2))
        for i, obj in enumerate(self.objects):
            t, u, v = obj.intersect(origins, dirs)
            closer = t < best
            best = np.where(closer, t, best)
            index = np.where(closer, i, index)
            coords[closer] = np.stack([u[closer], v[closer]], axis=1)
        rgb = np.zeros((n, 3), dtype=np.float32)
        for i, obj in enumerate(self.objects):
            mask = index == i
            if mask.any():
                rgb[mask] = obj.colour(coords[mask, 0], coords[mask, 1])
        sky = index < 0
        if sky.any():
            rgb[sky] = self.sky.colour(dirs[sky])
        depth = np.where(sky, np.inf, -(origins[:, 2] + best * dirs[:, 2]))
        return rgb, depth, index


# --- builders: place objects by virtual-camera pixel position and distance --------------------------------------
def _texel_for(rig: Rig, distance_m: float, oversample: float = 1.5) -> float:
    """Texel size (mm) finer than a pixel's footprint at ``distance_m`` by ``oversample``."""
    return distance_m * 1000.0 * rig.pixel_size_mm / rig.focal_mm / oversample


def plane(rig: Rig, distance_m: float, texture: np.ndarray, *, centre_px=None, size_px=None, elliptic=False,
          tilt_deg: float = 0.0, pan_deg: float = 0.0, gain: float = 1.0, fit_texture: bool = False,
          name: str = "plane") -> Patch:
    """A patch whose centre is seen at virtual pixel ``centre_px`` (default: image centre) at ``distance_m``.

    ``size_px`` (w, h) bounds it to about that many pixels on the image (None: unbounded); ``tilt_deg``
    rotates it about the horizontal axis (top away from the viewer), ``pan_deg`` about the vertical one.
    ``fit_texture`` stretches one copy of the texture over the (bounded) patch, e.g. a photograph; otherwise
    the texture tiles with texels 1.5x finer than a pixel's footprint.
    """
    centre_px = rig.centre if centre_px is None else np.asarray(centre_px, dtype=np.float64)
    origin = rig.image_to_world(centre_px, rig.disparity(distance_m))
    tilt, pan = np.radians(tilt_deg), np.radians(pan_deg)
    u_axis = np.array([np.cos(pan), 0.0, np.sin(pan)])
    v_axis = np.array([0.0, np.cos(tilt), -np.sin(tilt)])
    v_axis -= (v_axis @ u_axis) * u_axis
    v_axis /= np.linalg.norm(v_axis)
    footprint = distance_m * 1000.0 * rig.pixel_size_mm / rig.focal_mm  # mm per pixel
    half = (np.inf, np.inf) if size_px is None else (size_px[0] / 2 * footprint, size_px[1] / 2 * footprint)
    texel = _texel_for(rig, distance_m)
    if fit_texture and size_px is not None:
        texel = 2.0 * max(half) / texture.shape[0]
    return Patch(origin, u_axis, v_axis, texture, texel, half, elliptic, gain, name)
