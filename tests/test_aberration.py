"""Synthetic aberrations and their correction kernels (tpnet_gpu/aberration.py).

Oracles: closed-form Gaussian moments, scipy.signal.convolve2d (kernel * PSF), numpy FFT blurs of periodic
textures (tests/textures.py), known sub-pixel shifts, ``tables.kernel_to_clt`` per kernel, and the processor
without kernels (identity). Widths and shifts are measured on the processor's 15x15 correlations; every bound
below states the value measured when it was set.
"""

import numpy as np
import pytest
from scipy.signal import convolve2d

from tests.textures import smooth_noise
from tpnet_gpu import aberration as ab
from tpnet_gpu import tables
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor

H, W = 64, 64
# Two cameras looking at the same spot: pair (0, 1) is then an autocorrelation, or a colour-to-colour
# correlation when the "cameras" are two colour planes of one camera.
SAME_SPOT = dict(camera_offsets=[(0, 0), (0, 0)], pairs=[(0, 1)])
# Fat zero far above every |X| (~1e2 for unit-std textures): the normalisation divides by a constant, so the
# correlation is a plain (windowed, low-passed) cross-correlation and its width shows the image's blur.
PLAIN = CorrelationConfig(fat_zero=1e6)


# --- helpers -------------------------------------------------------------------------------------------
def periodic_blur(image: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """FFT convolution of a periodic image ``(h, w)`` with a PSF (kernel_to_clt convention)."""
    h, w = image.shape
    r = psf.shape[-1] // 2
    grid = np.zeros((h, w))
    grid[: psf.shape[0], : psf.shape[1]] = psf
    grid = np.roll(grid, (-r, -r), axis=(0, 1))
    return np.fft.ifft2(np.fft.fft2(image) * np.fft.fft2(grid)).real


def render_field(image: np.ndarray, psfs: np.ndarray) -> np.ndarray:
    """Space-variant blur: each 16 x 16 block blurred by its node's PSF ``psfs (rows, cols, s, s)``."""
    out = np.empty_like(image)
    for y0 in range(0, image.shape[0], ab.KERNEL_STEP):
        for x0 in range(0, image.shape[1], ab.KERNEL_STEP):
            row, col = ab.kernel_node(x0, y0, *psfs.shape[:2])
            block = (slice(y0, y0 + ab.KERNEL_STEP), slice(x0, x0 + ab.KERNEL_STEP))
            out[block] = periodic_blur(image, psfs[row, col])[block]
    return out


def interior(tp: TileProcessor, out) -> np.ndarray:
    """Correlations ``(n, 15, 15)`` of pair 0 in the valid tiles: those whose windows lie inside the frame."""
    valid = out.valid.cpu().numpy()
    assert valid.sum() == (tp.tiles_y - 2) * (tp.tiles_x - 2)
    return out.corr.cpu().numpy()[:, 0][valid]


def fwhm(corr: np.ndarray) -> float:
    """Full width at half maximum of the peak at (7, 7), px: mean over the x and y axes, linear interpolation."""

    def half_width(profile):  # profile[0] is the centre
        half = 0.5 * profile[0]
        for i in range(1, len(profile)):
            if profile[i] < half:
                return i - 1 + (profile[i - 1] - half) / (profile[i - 1] - profile[i])
        return float(len(profile) - 1)

    c = tables.CORR_RADIUS
    row, col = corr[c], corr[:, c]
    return 0.5 * sum(half_width(p) for p in (row[c:], row[c::-1], col[c:], col[c::-1]))


def peak_position(corr: np.ndarray) -> np.ndarray:
    """(x, y) lag of the peak: argmax within +-3 lags, then a 3-point parabola per axis."""
    c = tables.CORR_RADIUS
    centre = corr[c - 3 : c + 4, c - 3 : c + 4]
    iy, ix = np.unravel_index(np.argmax(centre), centre.shape)
    iy, ix = iy + c - 3, ix + c - 3

    def vertex(a, b, d):
        return 0.5 * (a - d) / (a - 2 * b + d)

    return np.array([ix - c + vertex(*corr[iy, ix - 1 : ix + 2]), iy - c + vertex(*corr[iy - 1 : iy + 2, ix])])


def tile_centres(height: int, width: int) -> np.ndarray:
    """``(tiles, 2)`` tile centres (x, y) = (8 tx + 4, 8 ty + 4)."""
    ty, tx = np.mgrid[0 : height // 8, 0 : width // 8]
    return np.stack([8 * tx + 4, 8 * ty + 4], axis=-1).reshape(-1, 2).astype(np.float64)


# --- PSFs ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("sigma, shift", [(0.7, (0.0, 0.0)), (1.5, (0.7, -0.3)), (1.0, (-2.2, 1.4))])
def test_gaussian_psf_moments(sigma, shift):
    # Oracle: a pixel-integrated Gaussian has mean = shift and variance sigma^2 + 1/12 (Sheppard), here to 1e-3.
    psf = ab.gaussian_psf(sigma, shift)
    assert psf.shape[0] % 2 == 1 and psf.shape[0] <= 15
    assert psf.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(ab.psf_centroids(psf), shift, atol=1e-3)
    r = psf.shape[0] // 2
    d = np.arange(-r, r + 1)
    var_x = (psf.sum(axis=0) * (d - shift[0]) ** 2).sum()
    assert var_x == pytest.approx(sigma**2 + 1 / 12, abs=1e-3)


def test_gaussian_psf_of_zero_sigma_is_a_delta():
    psf = ab.gaussian_psf(0.0, size=5)
    assert psf[2, 2] == 1.0 and psf.sum() == 1.0
    assert ab.gaussian_psf(0.0, (1.0, 0.0), size=5)[2, 3] == 1.0  # content moved one pixel right


def test_field_psfs_layout_blur_and_lateral_ca():
    ca = 1.5
    psfs = ab.field_psfs(H, W, 2, sigma_centre=0.6, sigma_edge=1.4, lateral_ca=ca)
    rows, cols = ab.kernel_grid_shape(H, W)
    assert (rows, cols) == (H // 16 + 2, W // 16 + 2)
    assert psfs.shape[:4] == (2, rows, cols, 3) and psfs.shape[-1] % 2 == 1
    np.testing.assert_allclose(psfs.sum(axis=(-2, -1)), 1.0, atol=1e-12)
    np.testing.assert_array_equal(psfs[0], psfs[1])  # identical cameras
    # Oracle: R at +ca (u, v), B at -ca (u, v), G at 0, (u, v) = node offset from the frame centre / half diagonal.
    ny, nx = ab.node_centres(rows, cols)
    np.testing.assert_array_equal(nx, 16 * np.arange(cols) - 8)
    u = (nx[None, :] - W / 2) / (0.5 * np.hypot(H, W))
    v = (ny[:, None] - H / 2) / (0.5 * np.hypot(H, W))
    centroids = ab.psf_centroids(psfs[0])  # (rows, cols, 3, 2)
    # atol: the 15 x 15 crop trims the widest PSFs, on the margin ring's corners (measured 2.9e-3 there).
    np.testing.assert_allclose(centroids[..., 0, 0], ca * u + 0 * v, atol=5e-3)
    np.testing.assert_allclose(centroids[..., 0, 1], ca * v + 0 * u, atol=5e-3)
    np.testing.assert_allclose(centroids[..., 1, :], -centroids[..., 0, :], atol=1e-9)
    np.testing.assert_allclose(centroids[..., 2, :], 0.0, atol=1e-9)
    # Blur grows toward the edge: second moment of G at a corner node vs a node next to the centre.
    d = np.arange(psfs.shape[-1]) - psfs.shape[-1] // 2
    spread = (psfs[0, ..., 2, :, :].sum(axis=-2) * d**2).sum(axis=-1)  # (rows, cols) x variance of G
    assert spread[0, 0] > 2.0 * spread[2, 2]


@pytest.mark.parametrize(
    "x, y, node",
    [(4.0, 4.0, (1, 1)), (15.9, 16.0, (2, 1)), (-3.0, 100.0, (5, 0)), (63.5, 40.0, (3, 4)), (1e4, -1e4, (0, 5))],
)
def test_psf_at_uses_the_nearest_node_clamped(x, y, node):
    psfs = ab.field_psfs(H, W, 1, sigma_centre=0.5, sigma_edge=1.0, lateral_ca=1.0)
    assert ab.kernel_node(x, y, *psfs.shape[1:3]) == node
    np.testing.assert_array_equal(ab.psf_at(psfs, x, y), psfs[:, node[0], node[1]])
    ny, nx = ab.node_centres(*psfs.shape[1:3])
    if 0 <= x < W and 0 <= y < H:  # inside the frame the chosen node is the nearest one
        assert abs(nx[node[1]] - x) <= 8 and abs(ny[node[0]] - y) <= 8


# --- deconvolution kernels ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "sigma, shift, target_sigma, regularisation, bound",
    [
        (0.7, (0.0, 0.0), 0.5, 1e-3, 0.12),  # measured 0.089 (unrestored PSF vs target: 0.38)
        (1.0, (0.7, 0.0), 1.0, 1e-3, 0.06),  # measured 0.040 (0.46): a pure shift undone
        (1.5, (0.7, -0.4), 1.0, 1e-4, 0.20),  # measured 0.152 (0.56)
        (1.5, (0.0, 0.0), 0.5, 1e-3, 0.70),  # measured 0.657 (0.82): a target this narrow is only approached
    ],
)
def test_kernel_times_psf_approximates_the_target(sigma, shift, target_sigma, regularisation, bound):
    # Oracle: direct 2-D convolution (scipy) of the kernel with its PSF vs the target Gaussian, relative L2 error.
    psf = ab.gaussian_psf(sigma, shift, size=15)
    kernel = ab.deconvolution_kernels(psf, target_sigma=target_sigma, regularisation=regularisation)
    assert kernel.shape == (15, 15)
    restored = convolve2d(kernel, psf, mode="full")  # (29, 29), centred
    target = ab.gaussian_psf(target_sigma, size=29)
    error = np.linalg.norm(restored - target) / np.linalg.norm(target)
    unrestored = np.linalg.norm(np.pad(psf, 7) - target) / np.linalg.norm(target)
    assert error <= bound and error < 0.85 * unrestored
    assert restored.sum() == pytest.approx(1.0, abs=1e-12)  # flat fields keep their level


@pytest.mark.parametrize("shift", [(0.7, 0.0), (0.7, -0.4), (-1.8, 1.1)])
def test_kernel_moves_shifted_content_back(shift):
    # Oracle: the known PSF shift; centroid of kernel * PSF (scipy) within 0.05 px of 0 (measured <= 0.003).
    psf = ab.gaussian_psf(1.2, shift, size=15)
    restored = convolve2d(ab.deconvolution_kernels(psf), psf, mode="full")
    np.testing.assert_allclose(ab.psf_centroids(restored), 0.0, atol=0.05)
    np.testing.assert_allclose(ab.psf_centroids(ab.deconvolution_kernels(psf)), -np.array(shift), atol=0.01)
    # keep_shift: the kernel only sharpens; the content stays where the PSF put it (measured <= 0.002).
    kept = convolve2d(ab.deconvolution_kernels(psf, keep_shift=True), psf, mode="full")
    np.testing.assert_allclose(ab.psf_centroids(kept), shift, atol=0.05)


def test_kernels_undo_the_psf_gain_and_keep_leading_shape():
    psfs = 0.8 * ab.field_psfs(H, W, 2, sigma_centre=0.8, sigma_edge=1.2, lateral_ca=1.0)  # vignetting 0.8
    kernels = ab.deconvolution_kernels(psfs, size=11)
    assert kernels.shape == psfs.shape[:-2] + (11, 11)
    np.testing.assert_allclose(kernels.sum(axis=(-2, -1)) * psfs.sum(axis=(-2, -1)), 1.0, rtol=1e-12)


def test_clt_kernels_match_kernel_to_clt_per_kernel():
    rng = np.random.default_rng(3)
    pixel = rng.normal(size=(2, 3, 4, 3, 7, 7))
    clt = ab.clt_kernels(pixel)
    assert clt.shape == (2, 3, 4, 3, 4, 8, 8) and clt.dtype == np.float32
    want = np.stack([tables.kernel_to_clt(h) for h in pixel.reshape(-1, 7, 7)]).reshape(clt.shape)
    np.testing.assert_allclose(clt, want, rtol=0, atol=1e-5 * np.abs(want).max())
    assert ab.clt_kernels(pixel[:, 0, 0]).shape == (2, 3, 4, 8, 8)
    delta = np.zeros((2, 3, 5, 5))
    delta[..., 2, 2] = 1.0
    np.testing.assert_array_equal(ab.clt_kernels(delta), ab.identity_kernels(2))


# --- in the processor ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("grid", [None, ab.kernel_grid_shape(H, W)])
def test_identity_kernels_leave_processor_output_unchanged(device, grid):
    # Oracle: the processor without kernels; K_CC = 1 makes the product exact, so results are bit-identical.
    frames = np.random.default_rng(5).uniform(0, 4000, size=(4, H, W)).astype(np.float32)
    plain = TileProcessor(H, W, clt=True, device=device).process(frames, 1.5)
    corr, clt = plain.corr.cpu().clone(), plain.clt.cpu().clone()
    kernels = ab.identity_kernels(4, 3, grid=grid)
    assert kernels.shape == ((4, 3, 4, 8, 8) if grid is None else (4, *grid, 3, 4, 8, 8))
    out = TileProcessor(H, W, kernels=kernels, clt=True, device=device).process(frames, 1.5)
    np.testing.assert_array_equal(out.clt.cpu().numpy(), clt.numpy())
    np.testing.assert_array_equal(out.corr.cpu().numpy(), corr.numpy())


def _autocorrelation_fwhm(frame, cfa, kernels, device, config=PLAIN) -> float:
    """Mean FWHM over the interior tiles of the autocorrelation of ``frame`` seen by two identical cameras."""
    tp = TileProcessor(H, W, cfa=cfa, kernels=kernels, config=config, device=device, **SAME_SPOT)
    out = tp.process(np.stack([frame, frame]).astype(np.float32), 0.0)
    return float(np.mean([fwhm(c) for c in interior(tp, out)]))


@pytest.mark.parametrize("cfa", [None, "GRBG"])
def test_corrected_blur_correlates_as_sharply_as_unblurred(device, cfa):
    # The test. Oracle: the unblurred frame. Texture sigma 1 px, Gaussian PSF sigma 1.5 px (FFT, periodic),
    # default kernels (target 0.5 px, lambda 1e-3), plain correlation (PLAIN). Measured mean FWHM, seeds 0-2:
    # mono: sharp 3.31-3.54, blurred 5.39-6.14, corrected 3.59-3.77 (corrected / sharp 1.06-1.09);
    # GRBG: sharp 3.99-4.34, blurred 5.79-6.62, corrected 4.06-4.35 (1.00-1.02).
    # Lambda 1e-4 gives 0.84-0.93 x the sharp width (sharper than the texture itself).
    colours = 1 if cfa is None else 3
    texture = smooth_noise(np.random.default_rng(0), (H, W), 1.0)[0]  # grey scene: every colour the same
    psf = ab.gaussian_psf(1.5, size=15)
    blurred = periodic_blur(texture, psf)
    kernels = ab.clt_kernels(np.broadcast_to(ab.deconvolution_kernels(psf), (2, colours, 15, 15)))
    sharp = _autocorrelation_fwhm(texture, cfa, None, device)
    wide = _autocorrelation_fwhm(blurred, cfa, None, device)
    corrected = _autocorrelation_fwhm(blurred, cfa, kernels, device)
    # Seed 0 (tested): wide / sharp 1.73 (mono), 1.53 (GRBG); corrected / sharp 1.06, 1.00; corrected / wide
    # 0.61, 0.66 (seeds 1-2: up to 1.09 and 0.70).
    assert wide > 1.35 * sharp  # the blur is visible
    assert corrected <= 1.15 * sharp  # about as sharp as the unblurred frame
    assert corrected < 0.75 * wide  # and clearly sharper than the blurred one


def test_phase_correlation_alone_hides_blur(device):
    # Why the test above uses a huge fat zero: with fat_zero 0 each frequency is normalised to unit magnitude,
    # so an autocorrelation does not see the blur at all (measured FWHM 1.039 px sharp, 1.037 px blurred).
    texture = smooth_noise(np.random.default_rng(0), (H, W), 1.0)[0]
    blurred = periodic_blur(texture, ab.gaussian_psf(1.5, size=15))
    phase_only = CorrelationConfig(fat_zero=0.0)
    sharp = _autocorrelation_fwhm(texture, None, None, device, phase_only)
    wide = _autocorrelation_fwhm(blurred, None, None, device, phase_only)
    assert wide == pytest.approx(sharp, rel=0.01)


def _colour_shift(frames, kernels, device, centres=None) -> np.ndarray:
    """Per interior tile, the (x, y) peak of the correlation of 'camera' 0 (G plane) with 'camera' 1 (R or B)."""
    tp = TileProcessor(*frames.shape[1:], cfa=None, kernels=kernels, config=PLAIN, device=device, **SAME_SPOT)
    if centres is None:
        out = tp.process(frames.astype(np.float32), 0.0)
    else:
        out = tp.process(frames.astype(np.float32), centres=centres.astype(np.float32))
    return np.array([peak_position(c) for c in interior(tp, out)])


@pytest.mark.parametrize("colour", [0, 1])  # R, B
def test_kernels_restore_colour_registration(device, colour):
    # Lateral CA across a 128 x 128 field (1 px in the corners, 0.18 px more per 16-px block; rendered block by
    # block). Each colour plane is fed to a mono processor as one "camera" (G as camera 0, R or B as camera 1),
    # so pair 0's peak is the colour's shift against G (sign: tile_processor.md §6.4). Oracle: the PSF centroid
    # of each tile's node (psf_at), |shift| up to 0.62 px, mean 0.32 px.
    size = 128
    psfs = ab.field_psfs(size, size, 1, sigma_centre=0.8, sigma_edge=1.2, lateral_ca=1.0)[0]  # (rows, cols, 3, s, s)
    texture = smooth_noise(np.random.default_rng(1), (size, size), 1.0)[0]
    frames = np.stack([render_field(texture, psfs[:, :, 2]), render_field(texture, psfs[:, :, colour])])
    centres = tile_centres(size, size)
    shifts = np.array([ab.psf_centroids(ab.psf_at(psfs[None], x, y)[0, colour]) for x, y in centres])
    inside = np.zeros((size // 8, size // 8), dtype=bool)
    inside[1:-1, 1:-1] = True
    expected = shifts[inside.reshape(-1)]

    raw = _colour_shift(frames, None, device)
    # Measured: least-squares gain raw / expected 0.80-0.82 (window bias toward 0); single tiles are off by up to
    # 0.38 px where a tile's window straddles two blocks of different shift.
    gain = (raw * expected).sum() / (expected**2).sum()
    assert 0.65 <= gain <= 1.0

    pixel = ab.deconvolution_kernels(psfs[:, :, [2, colour]])  # (rows, cols, 2, 15, 15): G, then the colour
    corrected = _colour_shift(frames, ab.clt_kernels(np.moveaxis(pixel, 2, 0)[:, :, :, None]), device)
    # Measured: residual -0.12 x the shift (the kernel moves each tile's window with its content, see
    # deconvolution_kernels), mean |residual| 0.04 px (0.13 x the mean shift), max 0.17 px.
    assert np.abs(corrected).mean() <= 0.25 * np.abs(expected).mean()
    assert np.abs(corrected).max() <= 0.25

    # Moving camera 1's windows by the centroid and keeping the shift in the kernel removes that bias
    # (geometry_and_lma.md D.2 data_x/y): measured max residual 0.038-0.048 px.
    kept = ab.deconvolution_kernels(psfs[:, :, [2, colour]], keep_shift=True)
    moved = np.repeat(centres[:, None, :], 2, axis=1)
    moved[:, 1] += shifts
    registered = _colour_shift(frames, ab.clt_kernels(np.moveaxis(kept, 2, 0)[:, :, :, None]), device, moved)
    assert np.abs(registered).max() <= 0.08


# --- bad input -------------------------------------------------------------------------------------------------
_invert = ab.deconvolution_kernels


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: ab.gaussian_psf(-1.0), r"sigma: expected a finite number >= 0, got -1.0"),
        (lambda: ab.gaussian_psf(1.0, size=4), r"size: expected an odd integer >= 1, got 4"),
        (lambda: ab.gaussian_psf(1.0, (np.nan, 0.0)), r"shift: expected finite \(x, y\)"),
        (lambda: ab.gaussian_psf(0.5, (9.0, 0.0), size=5),
         r"shift: expected the PSF centre inside the 5x5 kernel, got \(9.0, 0.0\)"),
        (lambda: ab.field_psfs(H, W, 0, sigma_centre=1, sigma_edge=1, lateral_ca=0), r"cams: expected a positive"),
        (lambda: ab.field_psfs(H, W, 1, sigma_centre=1, sigma_edge=1, lateral_ca=0, size=17),
         r"size: expected an odd integer in 1..15, got 17"),
        (lambda: _invert(np.ones((4, 4))), r"psfs: expected \(\.\.\., s, s\) with s odd, got shape \(4, 4\)"),
        (lambda: _invert(np.ones((3, 5))), r"psfs: expected \(\.\.\., s, s\) with s odd, got shape \(3, 5\)"),
        (lambda: _invert(np.full((3, 3), np.inf)), r"psfs: expected finite values, got NaN or infinity"),
        (lambda: _invert(np.zeros((2, 3, 3))), r"psfs: expected every PSF to have a non-zero sum, got a sum of 0"),
        (lambda: _invert(np.ones((3, 3)), regularisation=0.0), r"regularisation: expected a finite number > 0"),
        (lambda: _invert(np.ones((3, 3)), target_sigma=np.nan), r"target_sigma: expected a finite number >= 0"),
        (lambda: _invert(np.ones((3, 3)), size=16), r"size: expected an odd integer in 1..15, got 16"),
        (lambda: _invert(ab.gaussian_psf(1.0, (3.0, 0.5)), size=7),
         r"psfs: expected centroids within \+-2.5 px for size 7 kernels, got \(3.000, 0.500\)"),
        (lambda: ab.psf_centroids(np.zeros((3, 3))), r"psfs: expected every PSF to have a non-zero sum"),
        (lambda: ab.psf_at(np.zeros((3, 3, 3, 3)), 0, 0), r"psfs: expected shape \(cams, rows, cols, colours, s, s\)"),
        (lambda: ab.clt_kernels(np.zeros((2, 3, 17, 17))), r"pixel_kernels: expected .* got shape \(2, 3, 17, 17\)"),
        (lambda: ab.clt_kernels(np.zeros((2, 3, 3, 5, 5))), r"pixel_kernels: expected .* got shape \(2, 3, 3, 5, 5\)"),
        (lambda: ab.identity_kernels(4, 2), r"colours: expected 1 \(mono\) or 3 \(R, B, G\), got 2"),
        (lambda: ab.identity_kernels(4, grid=(0, 3)), r"grid: expected \(rows >= 1, cols >= 1\), got \(0, 3\)"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()
