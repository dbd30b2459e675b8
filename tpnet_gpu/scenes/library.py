"""Built-in scenes: the demo scene and random scenes for data sets. Objects are placed by their position on the
virtual camera's image (fractions of the frame) and their distance, so a scene fits any sensor size."""

from __future__ import annotations

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes import textures as tx
from tpnet_gpu.scenes.curved import curved as curved_object
from tpnet_gpu.scenes.objects import Scene, Sky, plane


def _at(rig: Rig, fx: float, fy: float) -> np.ndarray:
    return np.array([fx * rig.width, fy * rig.height])


def _size(rig: Rig, fw: float, fh: float) -> tuple[float, float]:
    return (fw * rig.width, fh * rig.height)


def demo_scene(rig: Rig = Rig(), seed: int = 0) -> Scene:
    """A far textured wall (photo) under a sky, a slanted textured plane, a line pattern at mid range and
    foreground boxes with sharp edges (a photo and flat-coloured shapes) at 12-40 m."""
    rng = np.random.default_rng(seed)
    noise = tx.noise_texture(rng, 1024)
    objects = [
        plane(rig, 1500.0, tx.photo_texture("grass"), centre_px=_at(rig, 0.5, 0.75), size_px=_size(rig, 4, 0.75),
              name="far wall"),
        plane(rig, 120.0, noise, centre_px=_at(rig, 0.2, 0.62), size_px=_size(rig, 0.3, 0.45), tilt_deg=10,
              pan_deg=45, name="slanted plane"),
        plane(rig, 300.0, tx.lines_texture(rng, 1024), centre_px=_at(rig, 0.78, 0.35), size_px=_size(rig, 0.3, 0.3),
              name="line pattern"),
        plane(rig, 40.0, tx.photo_texture("astronaut"), centre_px=_at(rig, 0.62, 0.62), size_px=_size(rig, 0.22, 0.3),
              fit_texture=True, name="photo board"),
        plane(rig, 18.0, tx.edges_texture(rng, 1024), centre_px=_at(rig, 0.4, 0.82), size_px=_size(rig, 0.16, 0.2),
              name="near box"),
        plane(rig, 12.0, tx.photo_texture("coffee"), centre_px=_at(rig, 0.86, 0.8), size_px=_size(rig, 0.12, 0.16),
              elliptic=True, fit_texture=True, name="near disc"),
    ]
    return Scene(objects, Sky(texture=tx.noise_texture(rng, 256, beta=2.0)), name=f"demo-{seed}")


TEXTURE_KINDS = ("noise", "edges", "lines", "photo")


def random_texture(rng: np.random.Generator, kind: str | None = None, n: int = 512) -> np.ndarray:
    kind = kind or rng.choice(TEXTURE_KINDS)
    if kind == "noise":
        return tx.noise_texture(rng, n, beta=rng.uniform(0.8, 1.6), contrast=rng.uniform(0.1, 0.4))
    if kind == "edges":
        return tx.edges_texture(rng, n)
    if kind == "lines":
        return tx.lines_texture(rng, n)
    return tx.photo_texture(rng.choice(tx.PHOTOS))


def random_scene(rig: Rig, rng: np.random.Generator, *, objects: int | None = None,
                 near_m: float = 8.0, far_m: float = 3000.0, curved: float = 0.0) -> Scene:
    """A random scene: a far background (or sky) and ``objects`` patches at log-uniform distances in
    [near_m, far_m], some slanted, some elliptic, with random textures and sizes; each object is a sphere
    or an upright cylinder (``scenes.curved``) instead with probability ``curved``. ``curved`` 0 draws
    exactly the scenes it drew before curved objects existed (the data sets' seeds stay valid)."""
    count = int(rng.integers(3, 9)) if objects is None else objects
    items = []
    if rng.random() < 0.8:
        items.append(plane(rig, far_m * rng.uniform(0.5, 1.0), random_texture(rng), centre_px=_at(rig, 0.5, 0.8),
                           size_px=_size(rig, 4, rng.uniform(0.6, 1.2)), name="background"))
    for i in range(count):
        distance = float(np.exp(rng.uniform(np.log(near_m), np.log(far_m / 2))))
        if curved > 0 and rng.random() < curved:
            items.append(curved_object(
                rig, distance, random_texture(rng), centre_px=_at(rig, rng.uniform(0.05, 0.95), rng.uniform(0.1, 0.95)),
                size_px=_size(rig, rng.uniform(0.08, 0.5), rng.uniform(0.08, 0.5)),
                kind=str(rng.choice(("sphere", "cylinder"))), gain=rng.uniform(0.5, 1.3), name=f"object {i}"))
            continue
        slanted = rng.random() < 0.35
        items.append(plane(
            rig, distance, random_texture(rng),
            centre_px=_at(rig, rng.uniform(0.05, 0.95), rng.uniform(0.1, 0.95)),
            size_px=_size(rig, rng.uniform(0.08, 0.5), rng.uniform(0.08, 0.5)),
            tilt_deg=rng.uniform(-60, 60) if slanted else 0.0, pan_deg=rng.uniform(-70, 70) if slanted else 0.0,
            elliptic=bool(rng.random() < 0.25), gain=rng.uniform(0.5, 1.3), fit_texture=bool(rng.random() < 0.3),
            name=f"object {i}",
        ))
    return Scene(items, Sky(texture=tx.noise_texture(rng, 256, beta=2.0)), name="random")
