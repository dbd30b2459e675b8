"""Convert kernel (kernels/convert.py) against the golden reference (tests/kernels/oracle.py).

Tolerance: max |kernel - reference| <= 1e-5 x max |reference| (float32 kernel vs float64 reference;
measured ~1e-6)."""

import numpy as np
import pytest

from tests.kernels.oracle import reference_clt, relative_error
from tpnet_gpu import reference as ref
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor

H, W = 48, 64
TOL = 1e-5


def _frames(rng, cams=4, height=H, width=W):
    return rng.uniform(0, 1000, size=(cams, height, width)).astype(np.float32)


@pytest.mark.parametrize("cfa", ["GRBG", "RGGB", None])
def test_clt_equals_reference_on_random_disparities(device, backend, cfa):
    # Random per-tile disparities up to +-40 px: border tiles and windows pushed wholly off the image.
    rng = np.random.default_rng(10)
    frames = _frames(rng)
    disparity = rng.uniform(-6, 6, size=(H // 8, W // 8)).astype(np.float32)
    disparity[0, :3] = [40.0, -40.0, 17.3]
    tp = TileProcessor(H, W, cfa=cfa, clt=True, device=device, backend=backend)
    out = tp.process(frames, disparity)
    want = reference_clt(frames, out.centres.cpu().numpy(), cfa)
    assert out.clt.shape == (tp.tiles, 4, 1 if cfa is None else 3, 4, 8, 8)
    assert relative_error(out.clt, want) <= TOL


def test_clt_equals_reference_at_arbitrary_centres(device, backend):
    # Any centres, including far off the image and exact half-pixel corners (rounded half up).
    rng = np.random.default_rng(11)
    frames = _frames(rng, cams=3)
    tp = TileProcessor(H, W, camera_offsets=[(0, 0), (1, 0), (0, 1)], pairs=[(0, 1), (0, 2)], clt=True,
                       device=device, backend=backend)
    centres = rng.uniform(-20, 80, size=(tp.tiles, 3, 2)).astype(np.float32)
    centres[0, 0] = (-1000.0, 5000.0)
    centres[1, 1] = (20.5, 30.5)
    out = tp.process(frames, centres=centres)
    assert relative_error(out.clt, reference_clt(frames, centres, "GRBG")) <= TOL
    np.testing.assert_array_equal(out.centres.cpu().numpy(), centres)


def test_kernel_product_equals_reference(device, backend):
    rng = np.random.default_rng(12)
    frames = _frames(rng)
    h = rng.normal(size=(4, 2, 3, 3, 5, 5)) * 0.1  # (cams, rows, cols, colours, 5, 5) pixel-domain kernels
    h[..., 2, 2] += 1.0
    kernels = np.stack([ref.kernel_to_clt(k) for k in h.reshape(-1, 5, 5)]).reshape(4, 2, 3, 3, 4, 8, 8)
    tp = TileProcessor(H, W, kernels=kernels.astype(np.float32), clt=True, device=device, backend=backend)
    out = tp.process(frames, 1.5)
    want = reference_clt(frames, out.centres.cpu().numpy(), "GRBG", kernels=kernels)
    assert relative_error(out.clt, want) <= TOL


def test_window_validity_mask(device, backend, keep_clt):
    rng = np.random.default_rng(13)
    tp = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    valid = tp.process(_frames(rng), 0.0).valid.cpu().numpy().reshape(H // 8, W // 8)
    # At disparity 0 every camera reads pixels 8 tx - 4 .. 8 tx + 11: the outer ring of tiles is off the image.
    assert not valid[0].any() and not valid[-1].any() and not valid[:, 0].any() and not valid[:, -1].any()
    assert valid[1:-1, 1:-1].all()
    pushed = np.zeros((H // 8, W // 8), dtype=np.float32)
    pushed[2, 3] = 30.0  # camera 3 sees this tile 15 px up and left: its window starts at row -3
    valid = tp.process(_frames(rng), pushed).valid.cpu().numpy().reshape(H // 8, W // 8)
    assert not valid[2, 3] and valid[2, 4]


def test_nan_pixel_masks_only_the_tiles_that_read_it(device, backend, keep_clt):
    rng = np.random.default_rng(14)
    frames = _frames(rng)
    frames[1, 20, 30] = np.nan  # camera 1, inside the windows of tiles tx 3..4, ty 2..3 at disparity 0
    tp = TileProcessor(H, W, config=CorrelationConfig(fat_zero=0.0), clt=keep_clt, device=device, backend=backend)
    out = tp.process(frames, 0.0)
    valid = out.valid.cpu().numpy().reshape(H // 8, W // 8)
    assert not valid[2:4, 3:5].any() and valid[1, 1] and valid[4, 6]
    corr = out.corr.cpu().numpy().reshape(H // 8, W // 8, 6, 15, 15)
    assert np.all(corr[2:4, 3:5] == 0) and np.isfinite(corr).all() and np.abs(corr[1, 1]).max() > 0
    assert out.clt is None if not keep_clt else np.isfinite(out.clt.cpu().numpy()).all()


def test_nan_disparity_masks_the_tile(device, backend, keep_clt):
    rng = np.random.default_rng(15)
    disparity = np.zeros((H // 8, W // 8), dtype=np.float32)
    disparity[2, 2] = np.nan
    tp = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    out = tp.process(_frames(rng), disparity)
    valid = out.valid.cpu().numpy().reshape(H // 8, W // 8)
    assert not valid[2, 2] and valid[2, 3]
    assert np.all(out.corr.cpu().numpy().reshape(H // 8, W // 8, 6, 15, 15)[2, 2] == 0)
