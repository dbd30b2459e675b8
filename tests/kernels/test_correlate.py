"""Correlate and network-layer kernels (kernels/correlate.py) against the golden reference, and the whole
tile processor against a physical fact: a textured plane at a known disparity (Fourier-shifted views).

Tolerance: max |kernel - reference| <= 1e-5 x max |reference|."""

import numpy as np
import pytest

from tests.kernels.oracle import reference_clt, reference_corr, relative_error
from tests.reference.peaks import centroid_peak
from tests.textures import fourier_shift, mosaic, smooth_noise
from tpnet_gpu import reference as ref
from tpnet_gpu import tables
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor

H, W = 48, 64
TOL = 1e-5


@pytest.mark.parametrize(
    "cfa, config",
    [
        ("GRBG", CorrelationConfig()),  # spec defaults: fat zero 30, weights (0.25, 0.25, 0.5)
        ("GRBG", CorrelationConfig(fat_zero=0.0, colour_weights=(0.5, 0.2, 0.3), sigma_rb=0.7, sigma_corr=1.2)),
        ("GRBG", CorrelationConfig(colour_weights=(0.0, 0.0, 1.0), fat_zero=1.0e4)),  # BASELINE: green only
        ("GRBG", CorrelationConfig(colour_weights=(0.7, 0.0, 0.3))),  # R and G: the R+B low-pass without B
        (None, CorrelationConfig(fat_zero=5.0)),
    ],
)
def test_corr_and_layers_equal_reference(device, backend, keep_clt, cfa, config):
    rng = np.random.default_rng(20)
    frames = rng.uniform(0, 1000, size=(4, H, W)).astype(np.float32)
    disparity = rng.uniform(-4, 4, size=(H // 8, W // 8)).astype(np.float32)
    tp = TileProcessor(H, W, cfa=cfa, config=config, clt=keep_clt, device=device, backend=backend)
    out = tp.process(frames, disparity)
    clt = reference_clt(frames, out.centres.cpu().numpy(), cfa)
    c = tp.config
    want = reference_corr(clt, tables.QUAD_PAIRS, colour_weights=c.colour_weights, fat_zero=c.fat_zero,
                          sigma_rb=c.sigma_rb, sigma_corr=c.sigma_corr)
    assert out.corr.shape == (tp.tiles, 6, 15, 15)
    assert relative_error(out.corr, want) <= TOL
    assert out.layers.shape == (tp.tiles, 4, 9, 9)
    assert relative_error(out.layers, ref.network_layers(want, offset=c.net_offset)) <= TOL


def test_custom_pairs_and_cameras(device, backend, keep_clt):
    rng = np.random.default_rng(21)
    frames = rng.uniform(0, 1000, size=(2, H, W)).astype(np.float32)
    tp = TileProcessor(H, W, camera_offsets=[(-0.5, 0.0), (0.5, 0.0)], pairs=[(0, 1), (1, 0)], clt=keep_clt,
                       device=device, backend=backend)
    out = tp.process(frames, 2.0)
    want = reference_corr(reference_clt(frames, out.centres.cpu().numpy(), "GRBG"), [(0, 1), (1, 0)], fat_zero=30.0)
    assert relative_error(out.corr, want) <= TOL
    assert out.layers is None  # network layers exist only for the quad's 6 pairs


def test_network_layers_hand_case():
    # network.md §1 combination on a hand-computed 2-tile case: sqrt((a+o)(b+o)) - o, 0 unless both > 0.
    corr = np.zeros((1, 6, 15, 15))
    corr[0, 0, 7, 7], corr[0, 1, 7, 7] = 0.3, 0.5
    corr[0, 2, 7, 7], corr[0, 3, 7, 7] = 0.4, -0.1
    corr[0, 4, 3, 3] = 0.25  # (3, 3) of 15x15 = (0, 0) of the 9x9 crop
    layers = ref.network_layers(corr, offset=0.1)
    assert layers[0, 0, 4, 4] == pytest.approx(np.sqrt(0.4 * 0.6) - 0.1)
    assert layers[0, 1, 4, 4] == 0.0
    assert layers[0, 2, 0, 0] == 0.25
    assert ref.network_layers(corr, offset=-1.0)[0, 1, 4, 4] == pytest.approx(0.15)


def test_measures_a_plane_at_known_disparity(device, backend, keep_clt):
    """Physical oracle: four views of a band-limited Bayer texture moved by -d r_i (geometry_and_lma.md A.2).
    Correlating at a wrong target T, every pair's peak sits at -(d - T) x pair axis (geometry_and_lma.md B.2);
    refining with the 5x5 centroid converges to d within 0.05 px (median over the interior tiles)."""
    rng = np.random.default_rng(22)
    size, d_true = 64, 1.7
    colour = smooth_noise(rng, (size, size), 1.5) + 0.3 * smooth_noise(rng, (size, size), 1.5, channels=3)
    offsets = np.array(tables.QUAD_OFFSETS)
    frames = np.stack([mosaic(fourier_shift(colour, *(-d_true * r))) * 100 + 500 for r in offsets])
    tp = TileProcessor(size, size, config=CorrelationConfig(fat_zero=0.0), clt=keep_clt, device=device,
                       backend=backend)
    axes = np.array([offsets[b] - offsets[a] for a, b in tables.QUAD_PAIRS])
    target = np.zeros((size // 8, size // 8), dtype=np.float32)
    interior = (slice(1, -1), slice(1, -1))
    for n in range(6):
        out = tp.process(frames, target)
        corr = out.corr.cpu().numpy().reshape(size // 8, size // 8, 6, 15, 15)
        residual = np.zeros_like(target)
        for ty in range(1, size // 8 - 1):
            for tx in range(1, size // 8 - 1):
                peaks = np.array([centroid_peak(c) for c in corr[ty, tx]])
                if n == 0:  # sign of every pair at target 0: peak at -d x axis
                    assert np.all(np.sign(peaks[np.abs(axes) > 0]) == np.sign(-d_true * axes[np.abs(axes) > 0]))
                residual[ty, tx] = np.mean(-(peaks * axes).sum(1) / (axes * axes).sum(1))
        target = target + residual
    assert np.median(np.abs(target[interior] - d_true)) <= 0.05
