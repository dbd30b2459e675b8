"""A rig that moves between frames: the scene as the moved rig sees it, and the ground-truth flow of each camera
(motion_and_surfaces.md §2).

The renderer places the rig at the world origin, so a rig motion is rendered by moving the scene the other way:
the rig at frame t+1 sits at ``translation`` (world mm, x right, y up, z toward the viewer) turned by
``rotation`` (small angles, radians, about the rig's x, y, z axes, applied z then y then x); a world point P is
seen from there at ``R^T (P - T)``. The sky (at infinity) turns with the rig and ignores the translation.
Ground-truth flow (``true_flow``) projects the same world points at both times through the same camera model
(``Rig.world_to_image`` + ``Rig.port_coordinates``, distortion and extrinsics included): exact, not the estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tpnet_gpu.camera import Rig, grid_centres
from tpnet_gpu.scenes.objects import Patch, Scene, Sky

SKY_DISTANCE_MM = 1e12  # a sky ray's point for the projection: a parallax under 1e-6 px for any rig here


@dataclass(frozen=True)
class RigMotion:
    """The rig's pose at frame t+1 relative to frame t: ``translation`` (mm, world axes) and ``rotation`` (rad,
    (about x = tilt, about y = pan, about z = roll))."""

    translation: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """``(3, 3)`` rotation R of the rig (its axes in world coordinates): Rx Ry Rz."""
        ax, ay, az = (float(a) for a in self.rotation)
        rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
        ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
        rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
        return rx @ ry @ rz

    def to_rig(self, points: np.ndarray) -> np.ndarray:
        """World points ``(..., 3)`` -> the moved rig's frame: R^T (P - T)."""
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.translation, dtype=np.float64)) @ self.matrix()


@dataclass
class TurnedSky(Sky):
    """``base`` sky as a rig turned by ``rotation`` (R, the rig's axes) sees it: direction d' -> world R d'."""

    base: Sky | None = None
    rotation: np.ndarray | None = None

    def colour(self, dirs: np.ndarray) -> np.ndarray:
        return self.base.colour(dirs @ self.rotation.T)


def moved_scene(scene: Scene, motion: RigMotion) -> Scene:
    """``scene`` as the rig moved by ``motion`` sees it (every patch carried into the moved rig's frame)."""
    r = motion.matrix()
    patches = [replace(p, origin=motion.to_rig(p.origin), u_axis=p.u_axis @ r, v_axis=p.v_axis @ r)
               for p in scene.objects]
    for p in patches:
        if not isinstance(p, Patch):
            raise TypeError(f"scene: expected Patch objects, got {type(p).__name__}")
    return Scene(patches, TurnedSky(base=scene.sky, rotation=r), name=f"{scene.name} moved")


def _project(rig: Rig, cam: int, points: np.ndarray) -> np.ndarray:
    """Pixels ``(N, 2)`` of world points ``(N, 3)`` (the rig's frame) in camera ``cam``."""
    centre, d = rig.world_to_image(points)
    return rig.port_coordinates(centre, d)[:, cam]


def true_flow(scene: Scene, rig: Rig, motion: RigMotion, cam: int, pixels) -> np.ndarray:
    """Ground-truth flow ``(N, 2)`` (x, y px) of camera ``cam``'s pixels ``(N, 2)`` (corner based) from frame t
    (``scene``) to frame t+1 (the rig moved by ``motion``): where the surface point each pixel sees lands.

    Returns NaN where the pixel's ray leaves the scene's objects and the sky (none: the sky is everywhere)."""
    pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    origin = rig.lens_positions()[cam]
    dirs = rig.pixel_rays(cam, pixels)
    _, depth, _ = scene.trace(np.broadcast_to(origin, dirs.shape).copy(), dirs)
    t = np.where(np.isfinite(depth), (depth + origin[2]) / -dirs[:, 2], SKY_DISTANCE_MM / np.linalg.norm(dirs, axis=1))
    points = origin + t[:, None] * dirs
    moved = motion.to_rig(points)
    sky = ~np.isfinite(depth)
    moved[sky] = (points[sky] - origin) @ motion.matrix() + origin  # at infinity: the rotation only
    return _project(rig, cam, moved) - pixels


def tile_flow(scene: Scene, rig: Rig, motion: RigMotion, cam: int) -> np.ndarray:
    """``(tiles_y, tiles_x, 2)`` ground-truth flow (x, y px) of camera ``cam`` at the tile centres
    (8 tx + 4, 8 ty + 4) of its own image."""
    grid = (rig.height // 8, rig.width // 8)
    centres = grid_centres(*grid).reshape(-1, 2)
    return true_flow(scene, rig, motion, cam, centres).reshape(*grid, 2)
