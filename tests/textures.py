"""Test textures whose sub-pixel shifts are exact: periodic, band-limited noise shifted in the Fourier domain.

numpy.fft is the oracle for "content moved by (a_x, a_y)": J(x, y) = I(x - a_x, y - a_y) exactly for a periodic,
band-limited I.
"""

from __future__ import annotations

import numpy as np


def smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float, channels: int = 1) -> np.ndarray:
    """Gaussian-smoothed (std ``sigma`` px) periodic white noise, ``(channels, H, W)``, unit std per channel."""
    noise = rng.normal(size=(channels,) + tuple(shape))
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    gain = np.exp(-2.0 * (np.pi * sigma) ** 2 * (fx**2 + fy**2))
    out = np.fft.ifft2(np.fft.fft2(noise) * gain).real
    return out / out.std(axis=(-2, -1), keepdims=True)


def fourier_shift(image: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """Periodic image ``(..., H, W)`` with its content moved right by ``ax`` and down by ``ay`` pixels."""
    h, w = image.shape[-2:]
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    phase = np.exp(-2j * np.pi * (fx * ax + fy * ay))
    return np.fft.ifft2(np.fft.fft2(image) * phase).real


def mosaic(colour: np.ndarray, red: tuple[int, int] = (0, 1)) -> np.ndarray:
    """Bayer mosaic ``(H, W)`` of an image ``(3, H, W)`` in R, B, G order; R at parity ``red`` (GRBG default)."""
    _, h, w = colour.shape
    y = np.arange(h)[:, None] % 2
    x = np.arange(w)[None, :] % 2
    is_r = (y == red[0]) & (x == red[1])
    is_b = (y == 1 - red[0]) & (x == 1 - red[1])
    return np.where(is_r, colour[0], np.where(is_b, colour[1], colour[2]))
