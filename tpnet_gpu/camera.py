"""Multi-camera rig model (geometry_and_lma.md A): virtual centre camera, sub-camera offsets, radial distortion
and its inverse, per-camera extrinsic corrections, tile centres, disparity <-> distance, world <-> image.

Convention
----------
* Pixel coordinates are corner based (pixel (i, j) covers [i, i+1) x [j, j+1)); x right, y **down**.
* World coordinates (A.8) in millimetres: origin at the virtual centre camera's lens, x right, y **up**, z toward
  the viewer (points in front have z < 0).
* Disparity d (px) is the image shift between two adjacent cameras (square side = baseline B); camera i sees a
  virtual-camera point c at c - d r_i (ideal rig), r_i = camera offset in baselines (x right, y down).
* Lengths: ``pixel_size_mm``, ``focal_mm``, ``baseline_mm`` in mm. Float64 NumPy throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.layout import TILE_CENTRE, TILE_STRIDE

DISTORTION_TERMS = 7  # C, B, A, A5, A6, A7, A8: k(rho) = 1 + sum a_j (rho^(j+1) - 1)
EXTRINSIC_TERMS = 13  # tilt0..2, az0..2, roll0..3, zoom0..2 (radians; zoom = relative scale - 1)



def grid_centres(tiles_y: int, tiles_x: int) -> np.ndarray:
    """``(tiles_y, tiles_x, 2)`` float64 (x, y) pixel centres of a tile grid: tile (tx, ty) at (8 tx + 4, 8 ty + 4)."""
    ty, tx = np.meshgrid(np.arange(tiles_y), np.arange(tiles_x), indexing="ij")
    return np.stack([TILE_STRIDE * tx + TILE_CENTRE, TILE_STRIDE * ty + TILE_CENTRE], axis=-1).astype(np.float64)

@dataclass(frozen=True)
class Rig:
    """A rig of ``len(offsets)`` identical sensors (default: the Elphel quad, 258 mm baseline).

    Attributes:
        width, height: sensor size, pixels.
        pixel_size_mm, focal_mm: pixel pitch and focal length (F = focal / pixel in px).
        baseline_mm: square side B of the quad (the disparity unit's baseline).
        offsets: ``(cams, 2)`` r_i in baselines (x right, y down).
        distortion: (C, B, A, A5, A6, A7, A8) of the radial model, normalised by ``distortion_radius_mm``.
        distortion_radius_mm: R_d (half the sensor width by default).
        principal_points: ``(cams, 2)`` or None for the sensor centre (W/2, H/2).
        extrinsics: the 13-term "lazy eye" correction vector (A.5), radians; tilt3, az3, zoom3 follow from
            the others so that the rig centre does not move.
        rolls_deg: per-camera factory roll, degrees.
    """

    width: int = 2592
    height: int = 1936
    pixel_size_mm: float = 0.0022
    focal_mm: float = 4.5
    baseline_mm: float = 258.0
    offsets: tuple = tables.QUAD_OFFSETS
    distortion: tuple = (0.0,) * DISTORTION_TERMS
    distortion_radius_mm: float = 2.8512
    principal_points: tuple | None = None
    extrinsics: tuple = (0.0,) * EXTRINSIC_TERMS
    rolls_deg: tuple | None = None
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        if len(self.distortion) != DISTORTION_TERMS:
            raise ValueError(f"distortion: expected {DISTORTION_TERMS} terms (C, B, A, A5..A8), got {len(self.distortion)}")
        if len(self.extrinsics) != EXTRINSIC_TERMS:
            raise ValueError(f"extrinsics: expected {EXTRINSIC_TERMS} terms, got {len(self.extrinsics)}")
        offsets = np.asarray(self.offsets, dtype=np.float64)
        if offsets.ndim != 2 or offsets.shape[1] != 2:
            raise ValueError(f"offsets: expected shape (cams, 2), got {offsets.shape}")
        for name in ("pixel_size_mm", "focal_mm", "baseline_mm", "distortion_radius_mm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected a positive length, got {getattr(self, name)}")

    # --- basic quantities -------------------------------------------------------------------------------
    @property
    def cams(self) -> int:
        return len(self.offsets)

    @property
    def focal_px(self) -> float:
        """F = focal / pixel size, pixels."""
        return self.focal_mm / self.pixel_size_mm

    @property
    def centre(self) -> np.ndarray:
        """Optical centre of the virtual camera, (W/2, H/2)."""
        return np.array([self.width / 2.0, self.height / 2.0])

    def principal(self) -> np.ndarray:
        """``(cams, 2)`` principal points of the sensors."""
        if self.principal_points is None:
            return np.tile(self.centre, (self.cams, 1))
        return np.asarray(self.principal_points, dtype=np.float64).reshape(self.cams, 2)

    def offsets_array(self) -> np.ndarray:
        return np.asarray(self.offsets, dtype=np.float64)

    def is_ideal(self) -> bool:
        """No distortion, no extrinsic corrections or rolls, principal points at the centre."""
        return (not any(self.distortion) and not any(self.extrinsics) and not any(self.rolls_deg or ())
                and (self.principal_points is None or np.allclose(self.principal(), self.centre)))

    # --- disparity and distance (E) ------------------------------------------------------------------------
    def distance(self, disparity):
        """Distance Z (m) of a disparity (px): Z = f B / (d p). Infinite for d = 0."""
        d = np.asarray(disparity, dtype=np.float64)
        with np.errstate(divide="ignore"):
            return 0.001 * self.focal_mm * self.baseline_mm / (d * self.pixel_size_mm)

    def disparity(self, distance_m):
        """Disparity (px) of a distance (m): d = f B / (Z p)."""
        z = np.asarray(distance_m, dtype=np.float64)
        with np.errstate(divide="ignore"):
            return 0.001 * self.focal_mm * self.baseline_mm / (z * self.pixel_size_mm)

    # --- radial distortion (A.4) -----------------------------------------------------------------------------
    def _ratio(self, rho):
        """k(rho) = 1 + sum_j a_j (rho^(j+1) - 1), the distorted / undistorted radius ratio."""
        k = np.ones_like(rho)
        for j, a in enumerate(self.distortion):
            k = k + a * (rho ** (j + 1) - 1.0)
        return k

    def _ratio_derivative(self, rho):
        dk = np.zeros_like(rho)
        for j, a in enumerate(self.distortion):
            dk = dk + a * (j + 1) * rho**j
        return dk

    def distort(self, xy):
        """Undistorted (pinhole) pixel vectors from the optical axis ``(..., 2)`` -> distorted ones."""
        xy = np.asarray(xy, dtype=np.float64)
        rho = np.linalg.norm(xy, axis=-1, keepdims=True) * self.pixel_size_mm / self.distortion_radius_mm
        return xy * self._ratio(rho)

    def undistort(self, xy, iterations: int = 30):
        """Distorted pixel vectors ``(..., 2)`` -> undistorted (Newton on rho k(rho) = rho_d, float64).

        Raises ValueError where the model is not invertible (d(rho k)/d rho < 0.1, as the original's table).
        """
        xy = np.asarray(xy, dtype=np.float64)
        if not any(self.distortion):
            return xy.copy()
        scale = self.pixel_size_mm / self.distortion_radius_mm
        rho_d = np.linalg.norm(xy, axis=-1, keepdims=True) * scale
        rho = rho_d.copy()
        for _ in range(iterations):
            slope = self._ratio(rho) + rho * self._ratio_derivative(rho)
            if np.any(slope < 0.1):
                raise ValueError("distortion: the radial model is not invertible over this field (slope < 0.1)")
            rho = rho - (rho * self._ratio(rho) - rho_d) / slope
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(rho_d > 0, rho / np.where(rho_d > 0, rho_d, 1.0), 1.0 / self._ratio(np.zeros_like(rho)))
        return xy * ratio

    # --- extrinsic corrections (A.5) -------------------------------------------------------------------------
    def rotations(self) -> np.ndarray:
        """``(cams, 3, 3)`` matrices M_i = Rr Rt Ra applied to view vectors (x, y, F) in pixels."""
        if "rot" in self._cache:
            return self._cache["rot"]
        e = np.asarray(self.extrinsics, dtype=np.float64)
        cams = self.cams
        tilt = np.zeros(cams)
        az = np.zeros(cams)
        zoom = np.zeros(cams)
        roll = np.zeros(cams)
        n = min(cams - 1, 3)
        tilt[:n], az[:n], zoom[:n] = e[0:n], e[3 : 3 + n], e[10 : 10 + n]
        if cams == 4:  # the fourth camera keeps the rig centre fixed
            tilt[3], az[3], zoom[3] = -e[0:3].sum(), -e[3:6].sum(), -e[10:13].sum()
        roll[: min(cams, 4)] = e[6 : 6 + min(cams, 4)]
        if self.rolls_deg is not None:
            roll = roll + np.radians(np.asarray(self.rolls_deg, dtype=np.float64))
        out = np.zeros((cams, 3, 3))
        for i in range(cams):
            ca, sa, ct, st, cr, sr, z = np.cos(az[i]), np.sin(az[i]), np.cos(tilt[i]), np.sin(tilt[i]), \
                np.cos(roll[i]), np.sin(roll[i]), 1.0 + zoom[i]
            ra = np.array([[ca, 0, -sa], [0, 1, 0], [sa, 0, ca]])
            rt = np.array([[1, 0, 0], [0, ct, st], [0, -st, ct]])
            rr = np.array([[z * cr, z * sr, 0], [-z * sr, z * cr, 0], [0, 0, 1]])
            out[i] = rr @ rt @ ra
        self._cache["rot"] = out
        return out

    # --- port coordinates (A.6) -------------------------------------------------------------------------------
    def port_coordinates(self, centre, disparity) -> np.ndarray:
        """Pixel coordinates ``(..., cams, 2)`` in every sensor of virtual-camera points ``centre (..., 2)``
        (distorted, pixels) at ``disparity (...)``. With the ideal rig this is exactly c - d r_i."""
        centre = np.asarray(centre, dtype=np.float64)
        d = np.asarray(disparity, dtype=np.float64)[..., None, None]
        c = self.undistort(centre - self.centre)[..., None, :]  # (..., 1, 2)
        ci = c - d * self.offsets_array()  # (..., cams, 2)
        v = np.concatenate([ci, np.full(ci.shape[:-1] + (1,), self.focal_px)], axis=-1)
        w = np.einsum("cij,...cj->...ci", self.rotations(), v)
        q = self.focal_px * w[..., :2] / w[..., 2:3]
        return self.distort(q) + self.principal()

    def tile_centres(self, disparity) -> np.ndarray:
        """Per-camera tile centres ``(tiles, cams, 2)`` for target disparities ``(tiles_y, tiles_x)``;
        tile (tx, ty) is centred at (8 tx + 4, 8 ty + 4) in the virtual camera. NaN disparity gives NaN."""
        disparity = np.asarray(disparity, dtype=np.float64)
        centre = grid_centres(*disparity.shape)
        return self.port_coordinates(centre, disparity).reshape(-1, self.cams, 2)

    # --- rays and world points (A.8) -----------------------------------------------------------------------------
    def lens_positions(self) -> np.ndarray:
        """``(cams, 3)`` lens centres in world mm (x right, y up, z 0)."""
        r = self.offsets_array()
        return np.stack([r[:, 0] * self.baseline_mm, -r[:, 1] * self.baseline_mm, np.zeros(self.cams)], -1)

    def pixel_rays(self, cam: int, pixels) -> np.ndarray:
        """World directions ``(..., 3)`` (mm, z = -f) of sensor ``cam``'s pixel positions ``(..., 2)``
        (continuous, corner based; a pixel's centre is (i + 0.5, j + 0.5)). Inverts ``port_coordinates``."""
        q = self.undistort(np.asarray(pixels, dtype=np.float64) - self.principal()[cam])
        w = np.concatenate([q, np.full(q.shape[:-1] + (1,), self.focal_px)], axis=-1)
        v = w @ np.linalg.inv(self.rotations()[cam]).T
        ci = self.focal_px * v[..., :2] / v[..., 2:3]  # undistorted view in the rig frame, px, y down
        p = self.pixel_size_mm
        return np.stack([ci[..., 0] * p, -ci[..., 1] * p, np.full(ci.shape[:-1], -self.focal_mm)], axis=-1)

    def virtual_rays(self, pixels) -> np.ndarray:
        """World directions ``(..., 3)`` of the virtual centre camera's (distorted) pixel positions."""
        ci = self.undistort(np.asarray(pixels, dtype=np.float64) - self.centre)
        p = self.pixel_size_mm
        return np.stack([ci[..., 0] * p, -ci[..., 1] * p, np.full(ci.shape[:-1], -self.focal_mm)], axis=-1)

    def world_to_image(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points ``(..., 3)`` mm -> (virtual-camera distorted pixels ``(..., 2)``, disparity ``(...)``)."""
        pts = np.asarray(points, dtype=np.float64)
        d = -self.focal_mm * self.baseline_mm / (pts[..., 2] * self.pixel_size_mm)
        c = np.stack([pts[..., 0], -pts[..., 1]], axis=-1) * d[..., None] / self.baseline_mm
        return self.distort(c) + self.centre, d

    def image_to_world(self, pixels, disparity) -> np.ndarray:
        """Virtual-camera pixels ``(..., 2)`` at ``disparity (...)`` -> world points ``(..., 3)`` mm."""
        d = np.asarray(disparity, dtype=np.float64)
        c = self.undistort(np.asarray(pixels, dtype=np.float64) - self.centre)
        z = -self.focal_mm * self.baseline_mm / (d * self.pixel_size_mm)
        return np.stack([c[..., 0] * self.baseline_mm / d, -c[..., 1] * self.baseline_mm / d, z], axis=-1)

    # --- reference camera and rig files (rig_file.md §5, §1) ------------------------------------------------
    def referenced_to(self, cam: int) -> Rig:
        """The same rig with every offset shifted by ``-offsets[cam]``, so that camera ``cam`` has offset (0, 0).

        The virtual camera - whose pixels the tile grid and the disparity maps are in - then sits at camera
        ``cam``'s lens: with the ideal geometry, camera ``cam``'s tile centres are exactly the tile grid
        (8 tx + 4, 8 ty + 4) at every disparity, and every camera's tile centres move by ``d * offsets[cam]``.
        Nothing else uses absolute offsets: disparity and distance, distortion, principal points, the
        extrinsic corrections and ``pixel_rays`` are unchanged, pair directions (offset differences) too;
        world coordinates (``lens_positions``, ``world_to_image``, ``image_to_world``) get their origin at
        camera ``cam``'s lens, so a world point's pixel in every camera stays the same.
        """
        if isinstance(cam, bool) or not isinstance(cam, (int, np.integer)) or not 0 <= cam < self.cams:
            raise ValueError(f"cam: expected a camera index in 0..{self.cams - 1}, got {cam!r}")
        r = self.offsets_array()
        shifted = tuple(tuple(float(v) for v in row) for row in r - r[cam])
        return replace(self, offsets=shifted, _cache={})

    def to_json(self) -> dict:
        """Plain-JSON description (for scene folders)."""
        return {
            "width": self.width, "height": self.height, "pixel_size_mm": self.pixel_size_mm,
            "focal_mm": self.focal_mm, "baseline_mm": self.baseline_mm,
            "offsets": [list(map(float, r)) for r in self.offsets], "distortion": list(self.distortion),
            "distortion_radius_mm": self.distortion_radius_mm,
            "principal_points": None if self.principal_points is None else self.principal().tolist(),
            "extrinsics": list(self.extrinsics), "rolls_deg": None if self.rolls_deg is None else list(self.rolls_deg),
        }

    @classmethod
    def from_json(cls, data: dict) -> Rig:
        """Inverse of ``to_json``; unknown keys are an error that names them."""
        known = {"width", "height", "pixel_size_mm", "focal_mm", "baseline_mm", "offsets", "distortion",
                 "distortion_radius_mm", "principal_points", "extrinsics", "rolls_deg"}
        extra = set(data) - known
        if extra:
            raise ValueError(f"rig: unknown keys {sorted(extra)}; expected some of {sorted(known)}")
        kw = dict(data)
        for key in ("offsets", "principal_points"):
            if kw.get(key) is not None:
                kw[key] = tuple(tuple(map(float, row)) for row in kw[key])
        for key in ("distortion", "extrinsics", "rolls_deg"):
            if kw.get(key) is not None:
                kw[key] = tuple(map(float, kw[key]))
        return cls(**kw)
