"""Curved scene objects for the renderer: textured spheres and upright cylinders - surfaces whose disparity bends
inside a tile and turns steep toward their outline, as real objects' do (the planar ``Patch`` cannot). Same
interface as ``Patch`` (``intersect``, ``colour``), world coordinates as ``tpnet_gpu.camera`` (mm, z toward the
viewer); the texture is wrapped by arc length, so one texel keeps ``texel_mm`` on the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes.objects import _texel_for
from tpnet_gpu.scenes.textures import sample


def _nearest_root(b: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The smaller positive root t of a t^2 + 2 b t + c = 0 per ray ``(N,)``; inf where none."""
    disc = b * b - a * c
    ok = disc >= 0
    root = np.sqrt(np.where(ok, disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        near, far = (-b - root) / a, (-b + root) / a
    t = np.where(near > 0, near, far)  # a ray from inside hits the far side (not in rendered scenes)
    return np.where(ok & (t > 0) & np.isfinite(t), t, np.inf)


@dataclass
class Sphere:
    """A sphere of ``radius`` mm about ``centre`` (world mm); texture coordinates u, v are arc lengths (mm)
    along longitude and latitude from the point facing the viewer."""

    centre: np.ndarray
    radius: float
    texture: np.ndarray
    texel_mm: float
    gain: float = 1.0
    name: str = "sphere"

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=np.float64)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray parameters t ``(N,)`` of the hits (inf where missed) and surface coordinates u, v (mm)."""
        rel = origins - self.centre
        t = _nearest_root(np.einsum("ij,ij->i", rel, dirs), np.einsum("ij,ij->i", rel, rel) - self.radius ** 2,
                          np.einsum("ij,ij->i", dirs, dirs))
        hit = rel + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        u = self.radius * np.arctan2(hit[:, 0], hit[:, 2])
        v = self.radius * np.arcsin(np.clip(hit[:, 1] / self.radius, -1.0, 1.0))
        return t, u, v

    def colour(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Reflectance ``(N, 3)`` at surface coordinates (mm)."""
        half = self.texture.shape[0] / 2.0
        return self.gain * sample(self.texture, u / self.texel_mm + half, -v / self.texel_mm + half)


@dataclass
class Cylinder(Sphere):
    """An upright (y-axis) cylinder of ``radius`` about ``centre``, ``half_height`` mm above and below it;
    u is the arc length around it, v the height (mm)."""

    half_height: float = np.inf
    name: str = "cylinder"

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rel = origins - self.centre
        flat_rel, flat_dirs = rel[:, [0, 2]], dirs[:, [0, 2]]
        t = _nearest_root(np.einsum("ij,ij->i", flat_rel, flat_dirs),
                          np.einsum("ij,ij->i", flat_rel, flat_rel) - self.radius ** 2,
                          np.einsum("ij,ij->i", flat_dirs, flat_dirs))
        hit = rel + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        t = np.where(np.abs(hit[:, 1]) <= self.half_height, t, np.inf)
        return t, self.radius * np.arctan2(hit[:, 0], hit[:, 2]), hit[:, 1]


def curved(rig: Rig, distance_m: float, texture: np.ndarray, *, centre_px, size_px, kind: str = "sphere",
           gain: float = 1.0, name: str = "curved") -> Sphere:
    """A sphere (``kind`` "sphere") or upright cylinder ("cylinder") whose nearest point is seen at virtual
    pixel ``centre_px`` at ``distance_m``; ``size_px`` (w, h): about that many pixels on the image (the
    sphere's diameter is the smaller one, the cylinder's the width). Texels are 1.5x finer than a pixel's
    footprint at ``distance_m``."""
    footprint = distance_m * 1000.0 * rig.pixel_size_mm / rig.focal_mm  # mm per pixel
    front = rig.image_to_world(np.asarray(centre_px, dtype=np.float64), rig.disparity(distance_m))
    radius = (min(size_px) if kind == "sphere" else size_px[0]) / 2.0 * footprint
    ray = front / np.linalg.norm(front)  # from the virtual camera's centre through the front point
    centre = front + radius * ray
    texel = _texel_for(rig, distance_m)
    if kind == "sphere":
        return Sphere(centre, radius, texture, texel, gain, name)
    if kind == "cylinder":
        return Cylinder(centre, radius, texture, texel, gain, name, half_height=size_px[1] / 2.0 * footprint)
    raise ValueError(f"kind: expected 'sphere' or 'cylinder', got {kind!r}")
