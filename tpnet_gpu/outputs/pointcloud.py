"""Depth and 3-D points of a tile map of disparities through the rig (geometry_and_lma.md E, A.8), and the
binary PLY file they are written to (docs/outputs.md).

Conventions: depth is the distance Z along the virtual camera's axis, metres (``Rig.distance``: Z = f B / (d p));
points are in the rig's world frame, metres: origin at the virtual camera's lens (the reference camera's lens
after ``Rig.referenced_to``), x right, y up, z toward the viewer, so points in front of the rig have z = -Z < 0.
Each measured tile gives one point, on the ray through its centre (8 tx + 4, 8 ty + 4) (distortion removed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.layout import TILE_STRIDE

GAMMA = 2.2  # texture colours to 8-bit: linear raw units / white, then this display gamma (as texture.png)


def _tile_map(values, name: str) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2:
        raise ValueError(f"{name}: expected a map (rows, columns) of tiles or pixels, got shape {values.shape}")
    return values


def depth(disparity, rig: Rig) -> np.ndarray:
    """Float32 depth Z, metres, of a disparity map (px; tiles or pixels, the same shape): NaN where the
    disparity is NaN (unmeasured), +inf where it is <= 0 (at or beyond infinity)."""
    d = _tile_map(disparity, "disparity")
    with np.errstate(invalid="ignore"):
        z = np.where(d > 0, rig.distance(np.where(d > 0, d, 1.0)), np.inf)
    return np.where(np.isnan(d), np.nan, z).astype(np.float32)


def tile_centres(shape) -> np.ndarray:
    """``(tiles_y, tiles_x, 2)`` pixel centres (x, y) = (8 tx + 4, 8 ty + 4) of the tiles of a map of ``shape``."""
    ty, tx = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    half = TILE_STRIDE / 2
    return np.stack([TILE_STRIDE * tx + half, TILE_STRIDE * ty + half], axis=-1).astype(np.float64)


def tile_colours(texture, white: float) -> np.ndarray:
    """``(tiles_y, tiles_x, 3)`` uint8 colours: the mean of the texture ``(C, H, W)`` (R, G, B, alpha or Y,
    alpha; raw units) over each tile's 8x8 step, alpha-weighted, divided by ``white`` and gamma-encoded.
    Sides that are not a multiple of 8 leave the last tiles their partial cells."""
    texture = np.asarray(texture, dtype=np.float64)
    if texture.ndim != 3 or texture.shape[0] not in (2, 4):
        raise ValueError(f"texture: expected (channels, H, W) with 2 (Y, alpha) or 4 (R, G, B, alpha) channels, "
                         f"got shape {texture.shape}")
    if not white > 0:
        raise ValueError(f"white: expected a positive level, got {white!r}")
    colour, alpha = texture[:-1], np.clip(np.nan_to_num(texture[-1]), 0, None)
    _, h, w = texture.shape
    ty, tx = -(-h // TILE_STRIDE), -(-w // TILE_STRIDE)
    pad = ((0, 0), (0, ty * TILE_STRIDE - h), (0, tx * TILE_STRIDE - w))
    weight = np.pad(alpha, pad[1:]).reshape(ty, TILE_STRIDE, tx, TILE_STRIDE)
    value = np.pad(np.nan_to_num(colour) * alpha, pad).reshape(-1, ty, TILE_STRIDE, tx, TILE_STRIDE)
    mean = value.sum(axis=(2, 4)) / np.maximum(weight.sum(axis=(1, 3)), 1e-12)  # (colours, ty, tx)
    if mean.shape[0] == 1:
        mean = np.repeat(mean, 3, axis=0)
    return (np.clip(mean / white, 0, 1) ** (1 / GAMMA) * 255 + 0.5).astype(np.uint8).transpose(1, 2, 0)


def tile_points(disparity, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """The tiles with a finite positive disparity as points: ``(points (n, 3) float64 metres, mask (tiles_y,
    tiles_x) bool)``, in the module docstring's frame, in row-major tile order."""
    d = _tile_map(disparity, "disparity")
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(d) & (d > 0)
    centres = tile_centres(d.shape)[mask]
    return rig.image_to_world(centres, d[mask]) / 1000.0, mask


def pixel_points(disparity, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """The pixels with a finite positive disparity (a per-pixel map ``(h, w)``, px) as points on the rays through
    the pixel centres (x + 0.5, y + 0.5): ``(points (n, 3) float64 metres, mask (h, w) bool)``, row-major."""
    d = _tile_map(disparity, "disparity")
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(d) & (d > 0)
    ys, xs = np.nonzero(mask)
    centres = np.stack([xs + 0.5, ys + 0.5], axis=-1).astype(np.float64)
    return rig.image_to_world(centres, d[mask]) / 1000.0, mask


def write_ply(path, points, colours=None, *, scalars: dict | None = None, comments=()) -> Path:
    """Write a binary little-endian PLY of ``points (n, 3)`` (float32 x, y, z), optional ``colours (n, 3)``
    uint8 (red, green, blue) and float32 per-point ``scalars`` (name -> ``(n,)``), with ``comments`` lines."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: expected shape (n, 3), got {points.shape}")
    n = len(points)
    fields = [(axis, "<f4", points[:, i]) for i, axis in enumerate("xyz")]
    if colours is not None:
        colours = np.asarray(colours)
        if colours.shape != (n, 3) or colours.dtype != np.uint8:
            raise ValueError(f"colours: expected uint8 of shape ({n}, 3), got {colours.dtype} {colours.shape}")
        fields += [(name, "u1", colours[:, i]) for i, name in enumerate(("red", "green", "blue"))]
    for name, values in (scalars or {}).items():
        values = np.asarray(values)
        if values.shape != (n,):
            raise ValueError(f"scalars[{name!r}]: expected shape ({n},), got {values.shape}")
        fields.append((name, "<f4", values))
    record = np.empty(n, dtype=[(name, kind) for name, kind, _ in fields])
    for name, _, values in fields:
        record[name] = values
    ply_type = {"<f4": "float", "u1": "uchar"}
    # PLY headers are ASCII: other characters of a comment (a file name) as Python escapes, never an error
    comments = [str(c).replace("\n", " ").encode("ascii", "backslashreplace").decode("ascii") for c in comments]
    header = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments),
              f"element vertex {n}", *(f"property {ply_type[kind]} {name}" for name, kind, _ in fields),
              "end_header"]
    path = Path(path)
    with path.open("wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(record.tobytes())
    return path
