"""Scene textures: square rasters of linear RGB reflectance in [0, 1], ``(n, n, 3)`` float32, R G B order.

Procedural (multi-scale noise, edges, line patterns) and real photographs shipped by scikit-image (public
domain or CC0: astronaut (NASA), coffee, chelsea, brick, grass, gravel). A texture is mapped onto an object
with a physical texel size; sampling wraps around (textures tile).
"""

from __future__ import annotations

import numpy as np

PHOTOS = ("astronaut", "coffee", "chelsea", "brick", "grass", "gravel")


def _spectral_noise(rng: np.random.Generator, n: int, beta: float, channels: int) -> np.ndarray:
    """Periodic noise with a 1/f^beta amplitude spectrum, zero mean, unit std, ``(channels, n, n)``."""
    f = np.fft.fftfreq(n)
    radius = np.sqrt(f[:, None] ** 2 + f[None, :] ** 2)
    radius[0, 0] = 1.0
    amplitude = radius ** (-beta)
    amplitude[0, 0] = 0.0
    spectrum = np.fft.fft2(rng.normal(size=(channels, n, n))) * amplitude
    out = np.fft.ifft2(spectrum).real
    return out / out.std(axis=(-2, -1), keepdims=True)


def _finish(rgb: np.ndarray) -> np.ndarray:
    return np.clip(np.moveaxis(rgb, 0, -1), 0.0, 1.0).astype(np.float32)


def noise_texture(rng: np.random.Generator, n: int = 1024, *, beta: float = 1.2, contrast: float = 0.25,
                  mean: float = 0.4, tint: float = 0.3) -> np.ndarray:
    """Multi-scale (fractal) noise: luminance with a 1/f^beta spectrum, slightly colour-tinted."""
    lum = _spectral_noise(rng, n, beta, 1)
    chroma = _spectral_noise(rng, n, beta + 0.5, 3)
    base = rng.uniform(0.7, 1.3, size=(3, 1, 1))
    return _finish(mean * base * (1.0 + contrast * lum + tint * contrast * chroma))


def edges_texture(rng: np.random.Generator, n: int = 1024, *, shapes: int = 60) -> np.ndarray:
    """Random axis-aligned and rotated rectangles of flat colours (sharp edges) over faint noise."""
    rgb = np.broadcast_to(rng.uniform(0.2, 0.6, size=(3, 1, 1)), (3, n, n)).copy()
    y, x = np.mgrid[0:n, 0:n].astype(np.float32)
    for _ in range(shapes):
        cx, cy = rng.uniform(0, n, 2)
        hw, hh = rng.uniform(n / 40, n / 8, 2)
        angle = rng.uniform(0, np.pi)
        u = (x - cx) * np.cos(angle) + (y - cy) * np.sin(angle)
        v = -(x - cx) * np.sin(angle) + (y - cy) * np.cos(angle)
        inside = (np.abs(u) < hw) & (np.abs(v) < hh)
        rgb[:, inside] = rng.uniform(0.05, 0.9, size=(3, 1))
    rgb *= 1.0 + 0.03 * _spectral_noise(rng, n, 1.0, 1)
    return _finish(rgb)


def lines_texture(rng: np.random.Generator, n: int = 1024, *, gratings: int = 3) -> np.ndarray:
    """Sums of sinusoidal and square-wave gratings at random angles and periods (line patterns)."""
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    lum = np.zeros((n, n))
    for _ in range(gratings):
        # periods that divide n keep the texture periodic (no seam when it tiles)
        period = n / rng.choice([16, 24, 32, 48, 64, 96])
        angle_steps = rng.integers(0, 8)
        kx, ky = np.round(n / period * np.array([np.cos(angle_steps * np.pi / 8), np.sin(angle_steps * np.pi / 8)]))
        phase = 2 * np.pi * (kx * x + ky * y) / n + rng.uniform(0, 2 * np.pi)
        wave = np.sin(phase)
        lum += np.sign(wave) if rng.random() < 0.5 else wave
    lum /= gratings
    base = rng.uniform(0.6, 1.2, size=(3, 1, 1))
    return _finish(0.45 * base * (1.0 + 0.6 * lum[None]))


def photo_texture(name: str = "astronaut") -> np.ndarray:
    """A photograph from scikit-image's data (sRGB decoded to linear light), ``(n, n, 3)`` cropped square."""
    if name not in PHOTOS:
        raise ValueError(f"name: expected one of {PHOTOS}, got {name!r}")
    from skimage import data  # noqa: PLC0415 - imported on use: it is slow to import

    image = getattr(data, name)().astype(np.float64) / 255.0
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=-1)
    side = min(image.shape[:2])
    image = image[:side, :side, :3]
    linear = np.where(image <= 0.04045, image / 12.92, ((image + 0.055) / 1.055) ** 2.4)
    return np.clip(linear, 0, 1).astype(np.float32)


def sample(texture: np.ndarray, u, v) -> np.ndarray:
    """Bilinear, wrapping lookup of ``texture (n, m, 3)`` at texel coordinates ``u`` (columns), ``v`` (rows),
    any matching shapes; returns ``(..., 3)`` float32."""
    rows, cols = texture.shape[:2]
    u = np.asarray(u, dtype=np.float64) - 0.5
    v = np.asarray(v, dtype=np.float64) - 0.5
    u0 = np.floor(u)
    v0 = np.floor(v)
    fu = (u - u0)[..., None].astype(np.float32)
    fv = (v - v0)[..., None].astype(np.float32)
    c0 = np.mod(u0, cols).astype(np.int64)
    r0 = np.mod(v0, rows).astype(np.int64)
    c1 = (c0 + 1) % cols
    r1 = (r0 + 1) % rows
    top = texture[r0, c0] * (1 - fu) + texture[r0, c1] * fu
    bottom = texture[r1, c0] * (1 - fu) + texture[r1, c1] * fu
    return top * (1 - fv) + bottom * fv
