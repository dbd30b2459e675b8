"""Synthetic lens aberrations and their correction kernels (geometry_and_lma.md D; tile_processor.md §5).

A *PSF set* describes the optics; ``deconvolution_kernels`` inverts it; ``clt_kernels`` puts the inverses in the
CLT form that ``TileProcessor(kernels=...)`` multiplies tiles by.

Convention
----------
* Pixel-domain kernels and PSFs are square, odd-sided arrays indexed ``h[dy + r, dx + r]`` (r = side // 2) with
  out(y, x) = sum h(dy, dx) in(y - dy, x - dx), as in ``tables.kernel_to_clt``: a PSF whose weight sits at
  dx = +1 moves content one pixel right. A PSF is the image of a point source at the kernel's centre.
* Colour order R, B, G (index 0, 1, 2); x right, y down; pixel centres at integer + 0.5 (corner based).
* Kernel grid (geometry_and_lma.md D.1, tile_processor.md §5.1): step ``KERNEL_STEP`` = 16 px, node n centred at
  pixel 16 n - 8 on each axis, one margin node on each side: ``rows = ceil(H / 16) + 2``,
  ``cols = ceil(W / 16) + 2``. A point (x, y) uses the nearest node ``(floor(y / 16) + 1, floor(x / 16) + 1)``,
  clamped to the grid - the rule the processor uses for a tile centred at (x, y) (``kernel_node``).
* PSF-set layout: ``(cams, rows, cols, 3, s, s)`` - camera, node row, node column, colour, then the s x s PSF.
  ``psf_at(psfs, x, y)`` returns the ``(cams, 3, s, s)`` slice for image point (x, y).

Units: sigmas, shifts and centroids in pixels. All host-side NumPy, float64 unless stated.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
from scipy.special import erf

from tpnet_gpu import tables

KERNEL_STEP = 16  # px between kernel-grid nodes
MAX_SIDE = 2 * tables.CORR_RADIUS + 1  # 15: the largest kernel kernel_to_clt accepts
FFT_SIZE = 64  # side of the periodic grid the inverse is computed on
FFT_BATCH = 4096  # kernels per FFT batch (bounds the temporary memory to ~100 MB)


# --- validation ------------------------------------------------------------------------------------------
def _square_stack(name: str, value, min_ndim: int = 2) -> np.ndarray:
    """``value`` as float64 ``(..., s, s)`` with s odd; finite. Raises ValueError naming ``name``."""
    a = np.asarray(value, dtype=np.float64)
    if a.ndim < min_ndim or a.shape[-1] != a.shape[-2] or a.shape[-1] % 2 != 1:
        raise ValueError(f"{name}: expected (..., s, s) with s odd, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected finite values, got NaN or infinity")
    return a


def _odd_side(name: str, size, limit: int | None = None) -> int:
    if not isinstance(size, (int, np.integer)) or size < 1 or size % 2 != 1 or (limit and size > limit):
        allowed = f"in 1..{limit}" if limit else ">= 1"
        raise ValueError(f"{name}: expected an odd integer {allowed}, got {size!r}")
    return int(size)


def _non_negative(name: str, value) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{name}: expected a finite number >= 0, got {value}")
    return value


# --- kernel grid -------------------------------------------------------------------------------------------
def kernel_grid_shape(height: int, width: int) -> tuple[int, int]:
    """``(rows, cols)`` of the kernel grid for a ``height`` x ``width`` frame: ceil(size / 16) + 2 each."""
    for name, value in (("height", height), ("width", width)):
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name}: expected a positive integer, got {value!r}")
    return -(-int(height) // KERNEL_STEP) + 2, -(-int(width) // KERNEL_STEP) + 2


def node_centres(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions of the grid nodes: ``(y (rows,), x (cols,))``, node n at 16 n - 8."""
    return (KERNEL_STEP * np.arange(rows) - KERNEL_STEP / 2, KERNEL_STEP * np.arange(cols) - KERNEL_STEP / 2)


def kernel_node(x: float, y: float, rows: int, cols: int) -> tuple[int, int]:
    """``(row, col)`` of the node nearest to image point (x, y): floor(. / 16) + 1, clamped to the grid."""
    row = min(max(math.floor(y / KERNEL_STEP) + 1, 0), rows - 1)
    col = min(max(math.floor(x / KERNEL_STEP) + 1, 0), cols - 1)
    return row, col


def psf_at(psfs, x: float, y: float) -> np.ndarray:
    """The PSFs (or kernels) that apply at image point (x, y): the nearest node's ``(cams, colours, s, s)`` slice.

    Args:
        psfs: ``(cams, rows, cols, colours, s, s)`` PSF set (``field_psfs``) or pixel kernels on the same grid.
        x, y: pixel position (corner based, x right, y down).
    """
    a = np.asarray(psfs)
    if a.ndim != 6:
        raise ValueError(f"psfs: expected shape (cams, rows, cols, colours, s, s), got {a.shape}")
    row, col = kernel_node(x, y, a.shape[1], a.shape[2])
    return a[:, row, col]


# --- synthetic PSFs ----------------------------------------------------------------------------------------
def _pixel_integrated_gaussians(sigmas: np.ndarray, shifts: np.ndarray, size: int) -> np.ndarray:
    """``(b, size, size)`` Gaussians of std ``sigmas`` (b,) centred at ``shifts`` (b, 2) = (x, y), each pixel
    holding the integral over its area; each sums to 1 (all zero if its centre lies far outside)."""
    r = size // 2
    edges = np.arange(-r, r + 2) - 0.5  # pixel d covers d - 1/2 .. d + 1/2
    sig = sigmas[:, None]

    def axis(centres: np.ndarray) -> np.ndarray:
        t = edges[None, :] - centres[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            cdf = np.where(sig > 0, 0.5 * (1.0 + erf(t / (math.sqrt(2.0) * sig))), (t >= 0).astype(np.float64))
        return np.diff(cdf, axis=-1)

    out = axis(shifts[:, 1])[:, :, None] * axis(shifts[:, 0])[:, None, :]
    total = out.sum(axis=(-2, -1), keepdims=True)
    return np.divide(out, total, out=np.zeros_like(out), where=total > 1e-12)


def default_psf_side(sigma: float, shift: float = 0.0) -> int:
    """Smallest odd side that holds +-(3 sigma + |shift| + 1) px, at most 15."""
    r = math.ceil(3.0 * sigma + abs(shift) + 1.0)
    return min(2 * r + 1, MAX_SIDE)


def gaussian_psf(sigma: float, shift=(0.0, 0.0), size: int | None = None) -> np.ndarray:
    """Pixel-integrated isotropic Gaussian PSF ``(size, size)`` centred at ``shift`` = (x, y) px, sum 1.

    Each pixel holds the Gaussian's integral over its area (``sigma = 0``: a box-sampled point, a delta when
    unshifted), so the variance per axis is about sigma^2 + 1/12. Truncation at the border is renormalised
    away. A PSF centred at +x moves content right (``tables.kernel_to_clt`` convention).

    Args:
        sigma: Gaussian std before pixel integration, px, >= 0.
        shift: (x, y) centre offset from the middle pixel, px.
        size: odd side; default ``default_psf_side(sigma, max |shift|)`` (at most 15).
    """
    sigma = _non_negative("sigma", sigma)
    s = np.asarray(shift, dtype=np.float64)
    if s.shape != (2,) or not np.all(np.isfinite(s)):
        raise ValueError(f"shift: expected finite (x, y), got {shift!r}")
    size = default_psf_side(sigma, float(np.abs(s).max())) if size is None else _odd_side("size", size)
    psf = _pixel_integrated_gaussians(np.array([sigma]), s[None], size)[0]
    if not psf.any():
        raise ValueError(f"shift: expected the PSF centre inside the {size}x{size} kernel, got ({s[0]}, {s[1]})")
    return psf


def field_psfs(
    height: int,
    width: int,
    cams: int,
    *,
    sigma_centre: float,
    sigma_edge: float,
    lateral_ca: float,
    size: int | None = None,
) -> np.ndarray:
    """A simple lens on the kernel grid: blur grows toward the edge, R and B shift radially (lateral CA).

    Node (row i, col j) is centred at pixel (x, y) = (16 j - 8, 16 i - 8). With (u, v) = (x - W/2, y - H/2) / R,
    R = half the frame diagonal (|(u, v)| = 1 in the frame's corners, a little more on the margin ring):
      * sigma = sigma_centre + (sigma_edge - sigma_centre) (u^2 + v^2) (all colours),
      * PSF centre: R at +lateral_ca (u, v), B at -lateral_ca (u, v), G at (0, 0) - proportional to the radius,
        ``lateral_ca`` px in the corners.
    Every camera gets the same optics. ``psfs[cam, i, j, colour]`` is the PSF used for the 16 x 16 block of
    pixels 16 (j-1) .. 16 j - 1, 16 (i-1) .. 16 i - 1 (``psf_at(psfs, x, y)``, ``kernel_node``): a renderer
    blurs each colour of each block with it, and ``deconvolution_kernels(psfs)`` inverts the set.

    Args:
        height, width: frame size, px.
        cams: number of cameras.
        sigma_centre, sigma_edge: Gaussian std (before pixel integration) on axis and in the corners, px, >= 0.
        lateral_ca: R centre shift in the corners, px (B gets the opposite); may be negative.
        size: odd PSF side <= 15; default fits the largest sigma and shift of the grid.

    Returns:
        ``(cams, rows, cols, 3, s, s)`` float64, colours R, B, G, each PSF summing to 1;
        ``(rows, cols) = kernel_grid_shape(height, width)``.
    """
    rows, cols = kernel_grid_shape(height, width)
    if not isinstance(cams, (int, np.integer)) or cams < 1:
        raise ValueError(f"cams: expected a positive integer, got {cams!r}")
    s0, s1 = _non_negative("sigma_centre", sigma_centre), _non_negative("sigma_edge", sigma_edge)
    ca = float(lateral_ca)
    if not math.isfinite(ca):
        raise ValueError(f"lateral_ca: expected a finite number, got {lateral_ca!r}")
    ny, nx = node_centres(rows, cols)
    half_diagonal = 0.5 * math.hypot(width, height)
    v, u = np.meshgrid((ny - height / 2) / half_diagonal, (nx - width / 2) / half_diagonal, indexing="ij")
    sigma = np.maximum(s0 + (s1 - s0) * (u**2 + v**2), 0.0)  # (rows, cols)
    sign = np.array([1.0, -1.0, 0.0])  # R, B, G
    shifts = ca * sign[None, None, :, None] * np.stack([u, v], axis=-1)[:, :, None, :]  # (rows, cols, 3, 2)
    if size is None:
        size = default_psf_side(float(sigma.max()), float(np.abs(shifts).max()))
    size = _odd_side("size", size, MAX_SIDE)
    sigmas = np.broadcast_to(sigma[:, :, None], (rows, cols, 3)).reshape(-1)
    out = _pixel_integrated_gaussians(sigmas, shifts.reshape(-1, 2), size).reshape(rows, cols, 3, size, size)
    if not np.all(out.sum(axis=(-2, -1)) > 0):
        raise ValueError(f"size: expected room for a lateral_ca of {ca} px, got a {size}x{size} kernel")
    return np.broadcast_to(out, (int(cams),) + out.shape).copy()


def psf_centroids(psfs) -> np.ndarray:
    """Centroid offsets (x, y) of PSFs or kernels ``(..., s, s)`` from their middle pixel, px: ``(..., 2)``.

    The diagnostic for lateral chromatic aberration (the original's center_x / center_y, D.2): R and B of
    ``field_psfs`` give +-lateral_ca (u, v), G gives (0, 0). Raises ValueError for a zero sum.
    """
    a = _square_stack("psfs", psfs)
    r = a.shape[-1] // 2
    d = np.arange(-r, r + 1, dtype=np.float64)
    total = a.sum(axis=(-2, -1))
    if np.any(total == 0):
        raise ValueError("psfs: expected every PSF to have a non-zero sum, got a sum of 0")
    cx = (a * d[None, :]).sum(axis=(-2, -1)) / total
    cy = (a * d[:, None]).sum(axis=(-2, -1)) / total
    return np.stack([cx, cy], axis=-1)


# --- inversion ---------------------------------------------------------------------------------------------
def _embed(a: np.ndarray, n: int) -> np.ndarray:
    """Odd-sided ``(b, s, s)`` kernels onto a periodic ``(b, n, n)`` grid with the middle pixel at (0, 0)."""
    r = a.shape[-1] // 2
    out = np.zeros(a.shape[:-2] + (n, n))
    out[..., : a.shape[-2], : a.shape[-1]] = a
    return np.roll(out, (-r, -r), axis=(-2, -1))


def _crop(a: np.ndarray, size: int) -> np.ndarray:
    """Centred ``(b, size, size)`` crop of periodic ``(b, n, n)`` kernels whose middle is at (0, 0)."""
    r = size // 2
    return np.roll(a, (r, r), axis=(-2, -1))[..., :size, :size]


def _taper(centres: np.ndarray, size: int, n: int) -> np.ndarray:
    """Separable cos^2 tapers ``(b, n, n)`` on the periodic grid, centred at ``centres`` (b, 2) = (x, y), as
    wide as fits inside the ``size`` crop (so the crop keeps each kernel symmetric about its own centre)."""
    d = np.fft.fftfreq(n, 1.0 / n)  # periodic offsets 0, 1, ..., n/2 - 1, -n/2, ..., -1
    out = np.ones((centres.shape[0], n, n))
    for axis in (0, 1):  # x, y
        c = centres[:, axis][:, None]
        half = np.maximum(size // 2 + 0.5 - np.abs(c), 1.0)
        t = d[None, :] - c
        w = np.where(np.abs(t) < half, np.cos(0.5 * np.pi * t / half) ** 2, 0.0)
        out *= w[:, None, :] if axis == 0 else w[:, :, None]
    return out


def deconvolution_kernels(
    psfs,
    *,
    target_sigma: float = 0.5,
    regularisation: float = 1e-3,
    size: int = MAX_SIDE,
    keep_shift: bool = False,
) -> np.ndarray:
    """Regularised inverse kernels k with k * psf ~= target, a Gaussian of std ``target_sigma`` at (0, 0).

    Per PSF, on a periodic 64 x 64 grid: K = conj(P) T / (|P|^2 + lambda P(0)^2) (Tikhonov, i.e. Wiener with
    a white noise-to-signal ratio ``lambda = regularisation``), P and T the DFTs of the PSF and of the
    pixel-integrated target ``gaussian_psf(target_sigma)``. The phase of conj(P) undoes the PSF's centre shift
    (lateral CA). The inverse is tapered by a cos^2 window centred where the kernel is (minus the PSF centroid),
    so that the crop to ``size`` x ``size`` keeps it symmetric and keeps the shift; its sum is then set to
    1 / sum(psf), so a flat field keeps its level. Cost: about 6 s per camera of a 2592 x 1936 grid (2 cores).

    What it can reach: frequencies where |P| << sqrt(lambda) stay lost, so a target much narrower than the PSF
    is only approached (for a sigma 1.5 px PSF, lambda 1e-3 cuts near 1.75 rad/px). Measured relative L2 error
    ||k * psf - target|| / ||target||: 0.09 (PSF sigma 0.7 -> target 0.5), 0.04 (PSF sigma 1 shifted 0.7 px ->
    target 1), 0.15 (PSF sigma 1.5 shifted (0.7, -0.4) -> target 1, lambda 1e-4) (tests/test_aberration.py).
    Smaller lambda recovers more and amplifies noise more (||k||_2 of the sigma 1.5 PSF's default kernel: 2.7).

    Applied in the CLT domain (``clt_kernels``), the kernel's shift moves each tile's window along with its
    content, which biases a correlation peak by about -0.1 to -0.2 x the undone shift (window bias). Set
    ``keep_shift`` to leave the shift in place (target centred on the PSF centroid, kernel only sharpens) for a
    processor that moves the source window by ``psf_centroids`` instead (geometry_and_lma.md D.2 data_x/y).

    Args:
        psfs: ``(..., s, s)`` PSFs, s odd <= 31 (e.g. ``(cams, rows, cols, 3, s, s)`` from ``field_psfs``);
            finite, each with a non-zero sum and (unless ``keep_shift``) its centroid within
            +-(size / 2 - 1) px of the middle pixel.
        target_sigma: std of the target Gaussian before pixel integration, px, >= 0.
        regularisation: lambda > 0, relative to the PSF's squared DC gain.
        size: odd side of the output kernels, <= 15.
        keep_shift: keep the PSF's centre shift instead of undoing it.

    Returns:
        ``(..., size, size)`` float64 pixel-domain kernels (``tables.kernel_to_clt`` convention).
    """
    a = _square_stack("psfs", psfs)
    size = _odd_side("size", size, MAX_SIDE)
    target_sigma = _non_negative("target_sigma", target_sigma)
    lam = float(regularisation)
    if not (math.isfinite(lam) and lam > 0):
        raise ValueError(f"regularisation: expected a finite number > 0, got {regularisation!r}")
    if a.shape[-1] > FFT_SIZE // 2:
        raise ValueError(f"psfs: expected a side <= {FFT_SIZE // 2}, got {a.shape[-1]}")
    lead = a.shape[:-2]
    flat = a.reshape((-1,) + a.shape[-2:])
    gains = flat.sum(axis=(-2, -1))
    if np.any(gains == 0):
        raise ValueError("psfs: expected every PSF to have a non-zero sum, got a sum of 0")
    shifts = psf_centroids(flat)  # (b, 2)
    reach = size / 2 - 1  # the taper of a kernel centred further out would not fit in the crop
    if not keep_shift and np.abs(shifts).max(initial=0.0) > reach:
        x, y = shifts[np.abs(shifts).max(axis=-1).argmax()]
        raise ValueError(
            f"psfs: expected centroids within +-{reach} px for size {size} kernels, got ({x:.3f}, {y:.3f})"
        )
    targets = shifts if keep_shift else np.zeros((1, 2))  # (b or 1, 2): where each target Gaussian sits

    def spectrum(kernels: np.ndarray) -> np.ndarray:
        return scipy.fft.rfft2(_embed(kernels, FFT_SIZE), workers=-1)

    out = np.empty((flat.shape[0], size, size))
    for start in range(0, flat.shape[0], FFT_BATCH):
        part = slice(start, start + FFT_BATCH)
        at = targets[part] if keep_shift else targets
        t = spectrum(_pixel_integrated_gaussians(np.full(len(at), target_sigma), at, FFT_SIZE // 2 - 1))
        p = spectrum(flat[part])
        k = np.conj(p) * t / (np.abs(p) ** 2 + lam * gains[part, None, None] ** 2)
        k = scipy.fft.irfft2(k, s=(FFT_SIZE, FFT_SIZE), workers=-1)
        out[part] = _crop(k * _taper(at - shifts[part], size, FFT_SIZE), size)
    out *= (1.0 / (gains * out.sum(axis=(-2, -1))))[:, None, None]
    return out.reshape(lead + (size, size))


# --- CLT form ----------------------------------------------------------------------------------------------
def clt_kernels(pixel_kernels) -> np.ndarray:
    """CLT form of pixel-domain kernels, ready for ``TileProcessor(kernels=...)`` (tile_processor.md §5.3).

    ``tables.kernel_to_clt`` is linear in the kernel, so it is applied to the s^2 unit kernels once and the
    batch is one matrix product.

    Args:
        pixel_kernels: ``(cams, rows, cols, colours, s, s)`` on the kernel grid, or ``(cams, colours, s, s)``
            (one per camera and colour); s odd <= 15; colours 3 (R, B, G) or 1 (mono); finite.

    Returns:
        float32 ``(cams, rows, cols, colours, 4, 8, 8)`` (or ``(cams, colours, 4, 8, 8)``), quadrants CC, SC,
        CS, SS.
    """
    k = _square_stack("pixel_kernels", pixel_kernels)
    if k.ndim not in (4, 6) or k.shape[-1] > MAX_SIDE:
        raise ValueError(
            "pixel_kernels: expected (cams, rows, cols, colours, s, s) or (cams, colours, s, s) with s odd "
            f"<= {MAX_SIDE}, got shape {k.shape}"
        )
    s = k.shape[-1]
    basis = np.stack([tables.kernel_to_clt(delta.reshape(s, s)) for delta in np.eye(s * s)])  # (s*s, 4, 8, 8)
    clt = k.reshape(-1, s * s) @ basis.reshape(s * s, -1)
    return clt.reshape(k.shape[:-2] + (4, 8, 8)).astype(np.float32)


def identity_kernels(cams: int, colours: int = 3, *, grid: tuple[int, int] | None = None) -> np.ndarray:
    """No-op CLT kernels (CC = 1, SC = CS = SS = 0): float32 ``(cams, colours, 4, 8, 8)``, or
    ``(cams, rows, cols, colours, 4, 8, 8)`` when ``grid = (rows, cols)`` is given."""
    if not isinstance(cams, (int, np.integer)) or cams < 1:
        raise ValueError(f"cams: expected a positive integer, got {cams!r}")
    if colours not in (1, 3):
        raise ValueError(f"colours: expected 1 (mono) or 3 (R, B, G), got {colours!r}")
    if grid is not None and (len(grid) != 2 or min(grid) < 1):
        raise ValueError(f"grid: expected (rows >= 1, cols >= 1), got {grid!r}")
    lead = (cams,) if grid is None else (cams, *(int(g) for g in grid))
    out = np.zeros(lead + (colours, 4, 8, 8), dtype=np.float32)
    out[..., 0, :, :] = 1.0
    return out
