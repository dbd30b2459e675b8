"""The differentiable tile processor (tpnet_gpu/differentiable/tile.py). Oracles: the float64 NumPy reference
(tpnet_gpu.reference: forward output, tolerance 1e-10 relative) and central finite differences
(torch.autograd.gradcheck in float64, atol 1e-6 / rtol 1e-4; the pixels in its fast mode) with respect to pixel
values and tile centres.
Break tried: the phase rotation's sign of a sine term flipped in ``_rotate`` (the forward tests fail);
the residual ``s`` detached from the centres (gradcheck of the centres fails: analytic 0)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tpnet_gpu import reference, tables
from tpnet_gpu.config import BASELINE_CORRELATION, CorrelationConfig
from tpnet_gpu.differentiable import tile

PAIRS = tables.QUAD_PAIRS


def _frame(rng, height=40, width=48, cams=4):
    mosaics = rng.uniform(100.0, 2000.0, (cams, height, width))
    # tile centres inside the image, residuals away from the window corner's integer steps (s = +-0.5)
    centres = rng.uniform(10.0, 30.0, (3, cams, 2)) + np.array([6.0, 0.0])
    frac = centres - np.floor(centres)
    centres = np.where(np.abs(frac - 0.5) < 0.1, centres + 0.25, centres)
    return mosaics, centres


@pytest.mark.parametrize("config", [CorrelationConfig().resolved(3), BASELINE_CORRELATION.resolved(3)],
                         ids=["colour", "green"])
def test_forward_equals_reference(config):
    rng = np.random.default_rng(1)
    mosaics, centres = _frame(rng)
    planes = np.stack([reference.bayer_planes(m) for m in mosaics])
    ref_tiles = [reference.convert_tiles(planes[c], centres[:, c])[0] for c in range(4)]
    ref = np.stack([reference.correlate(ref_tiles[a], ref_tiles[b], colour_weights=config.colour_weights,
                                        fat_zero=config.fat_zero, sigma_rb=config.sigma_rb,
                                        sigma_corr=config.sigma_corr) for a, b in PAIRS], axis=1)
    planes_t = tile.bayer_planes(torch.as_tensor(mosaics))
    assert np.allclose(planes_t.numpy(), planes, rtol=0, atol=0)
    corr, inside = tile.correlate(planes_t, torch.as_tensor(centres), PAIRS, config)
    assert corr.shape == ref.shape and bool(inside.all())
    assert np.max(np.abs(corr.numpy() - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_convert_equals_reference_with_kernels():
    rng = np.random.default_rng(2)
    planes = rng.normal(size=(3, 32, 40))
    centres = np.array([[12.2, 15.7], [20.9, 17.1], [3.0, 4.0]])  # the last window is clamped off the image
    kernels = rng.normal(size=(3, 3, 4, 8, 8))
    ref, inside = reference.convert_tiles(planes, centres, kernels)
    out, inside_t = tile.convert_tiles(torch.as_tensor(planes), torch.as_tensor(centres), torch.as_tensor(kernels))
    assert np.max(np.abs(out.numpy() - ref)) <= 1e-12 * np.max(np.abs(ref))
    assert inside_t.tolist() == inside.tolist() == [True, True, False]


@pytest.mark.slow
def test_gradcheck_pixels_and_centres():
    """Finite differences (torch.autograd.gradcheck, float64) of the pair correlations w.r.t. the pixels and the
    per-camera tile centres; a 2-tile, 2-camera frame keeps the Jacobian small."""
    rng = np.random.default_rng(3)
    mosaics, centres = _frame(rng, height=32, width=40, cams=2)
    config = CorrelationConfig().resolved(3)
    mosaics_t = torch.tensor(mosaics[:, 8:28, 8:32], requires_grad=True)  # a crop keeps the Jacobian small
    centres_t = torch.tensor(centres[:2] - 8.0, requires_grad=True)

    def corr(m, c):
        return tile.correlate(tile.bayer_planes(m), c, ((0, 1),), config)[0][..., 5:10, 5:10]

    assert torch.autograd.gradcheck(lambda c: corr(mosaics_t.detach(), c), (centres_t,), atol=1e-6, rtol=1e-4)
    # the pixels: 480 inputs, checked in gradcheck's fast mode (random projections of the same Jacobians)
    assert torch.autograd.gradcheck(lambda m: corr(m, centres_t.detach()), (mosaics_t,), atol=1e-6, rtol=1e-4,
                                    fast_mode=True)
