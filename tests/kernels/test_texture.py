"""Texture kernels (kernels/texture.py) against the golden reference (tpnet_gpu/reference/texture.py).

Tolerance 1e-5 x max |reference| per channel. The weights pick the best two cameras and the worst one by
argmax/argmin, which is discontinuous at ties; the comparison therefore uses scenes the cameras roughly agree
on, with diff_sigma scaled to the data (values ~1000: diff_sigma 50). With the original's diff_sigma 5 on such
data near-ties make float32 and float64 differ by up to ~5e-5 (measured)."""

import numpy as np
import torch
import pytest

from tests.kernels.oracle import reference_clt, relative_error
from tests.textures import fourier_shift, mosaic, smooth_noise
from tpnet_gpu import tables
from tpnet_gpu.config import TextureConfig
from tpnet_gpu.processor import TileProcessor, buffers
from tpnet_gpu.reference import texture as tex

H, W = 48, 64
OFFSETS = np.array(tables.QUAD_OFFSETS)


def _scene(rng, d):
    colour = 1000 + 400 * (smooth_noise(rng, (H, W), 1.5) + 0.3 * smooth_noise(rng, (H, W), 1.5, channels=3))
    return colour, np.stack([mosaic(fourier_shift(colour, *(-d * r))) for r in OFFSETS]).astype(np.float32)


def _check_against_reference(device, backend, cfa, diff_sigma, masked):
    rng = np.random.default_rng(50)
    _, frames = _scene(rng, 1.3)
    disparity = (1.3 + rng.uniform(-0.3, 0.3, size=(H // 8, W // 8))).astype(np.float32)
    for tile in masked:  # a masked tile: no contribution, its neighbours fade towards it
        disparity[tile] = np.nan
    config = TextureConfig(diff_sigma=diff_sigma)
    tp = TileProcessor(H, W, cfa=cfa, textures=True, texture_config=config, device=device, backend=backend)
    out = tp.process(frames, disparity)
    clt = reference_clt(frames, out.centres.cpu().numpy(), cfa)
    rgba = tex.texture_tiles(clt, OFFSETS, diff_sigma=diff_sigma)
    gain = tables.TEXTURE_OUTPUT_GAIN
    want = tex.texture_image(rgba.reshape(H // 8, W // 8, -1, 16, 16), np.isfinite(disparity), H, W, gain)
    if cfa:
        want = want[[0, 2, 1, 3]]  # output channels R, G, B, A
    assert out.texture.shape == want.shape
    for channel in range(want.shape[0]):
        assert relative_error(out.texture[channel], want[channel]) <= 1e-5


@pytest.mark.parametrize("cfa, diff_sigma", [("GRBG", 50.0), (None, 500.0)])
def test_texture_equals_reference(device, backend, cfa, diff_sigma):
    _check_against_reference(device, backend, cfa, diff_sigma, [(2, 3)])


@pytest.mark.parametrize("rows", [1, 2, 4])
def test_texture_in_bands_equals_reference(device, backend, rows, monkeypatch):
    """The texture is made one band of tile rows at a time (Buffers.TEXTURE_BAND_ROWS, 8): with bands of 1, 2
    and 4 rows (6 rows of tiles: 6, 3 and 2 bands, the last one short) it still equals the reference. Tiles
    (2, 3), (3, 6) and (4, 1) sit on band edges with one contributing neighbour (the alpha fades towards it),
    so a band that took the rows beyond its edges as contributing would differ (checked: it fails)."""
    monkeypatch.setattr(buffers, "TEXTURE_BAND_ROWS", rows)
    masked = [(2, 2), (2, 4), (1, 3), (3, 5), (3, 7), (4, 6), (4, 0), (4, 2), (3, 1)]
    _check_against_reference(device, backend, "GRBG", 50.0, masked)


def test_texture_alpha_drops_at_a_wrong_disparity(device, backend):
    # Physical fact: at the true disparity the cameras agree (alpha ~1), 1 px off they do not (measured 0.99
    # vs 0.64 with diff_sigma 2 on this scene; the default 5 gives 0.998 vs 0.89).
    rng = np.random.default_rng(51)
    colour, frames = _scene(rng, 1.3)
    tp = TileProcessor(H, W, textures=True, texture_config=TextureConfig(diff_sigma=2.0), device=device, backend=backend)
    inner = (slice(8, -8), slice(8, -8))
    right = tp.process(frames, 1.3).texture.cpu().numpy().copy()
    wrong = tp.process(frames, 2.3).texture.cpu().numpy()
    assert right[3][inner].mean() > 0.95 and wrong[3][inner].mean() < right[3][inner].mean() - 0.2
    green = right[1][inner]
    assert np.corrcoef(green.ravel(), colour[2][inner].ravel())[0, 1] > 0.95


def test_empty_texture_is_zero(device, backend):
    tp = TileProcessor(H, W, textures=True, device=device, backend=backend)
    frames = np.full((4, H, W), 100.0, dtype=np.float32)
    out = tp.process(frames, 0.0, active=np.zeros((H // 8, W // 8), dtype=bool))
    assert np.all(out.texture.cpu().numpy() == 0)


def test_texture_needs_the_flag():
    tp = TileProcessor(H, W, device="cpu")
    assert tp.process(np.zeros((4, H, W), np.float32), 0.0).texture is None
    with pytest.raises(RuntimeError, match="texture: this processor was built without textures=True"):
        tp.texture()


def test_texture_is_bit_reproducible(backend):
    # Oracle: the first call. The overlap-add is a fixed-order gather (no float atomics), so repeated calls on
    # any thread count (Taichi spreads over every core) give the same bits; with atomics 21 of 100 calls differed.
    rng = np.random.default_rng(7)
    frames = rng.uniform(0, 4000, size=(4, 48, 64)).astype(np.float32)
    disparity = rng.uniform(-2, 2, size=(6, 8)).astype(np.float32)
    tp = TileProcessor(48, 64, textures=True, device="cpu", backend=backend)
    first = tp.process(frames, disparity).texture.clone()
    for _ in range(8):
        torch.testing.assert_close(tp.process(frames, disparity).texture, first, rtol=0, atol=0)


@pytest.mark.parametrize("rows", [1, 2, 16])
def test_banded_convert_equals_whole_frame_texture(device, backend, rows, monkeypatch):
    """Without ``clt=True`` the texture converts band by band into a band of CLT tiles and keeps the RGBA
    contributions of ``rows + 1`` tile rows (a ring); oracle: the same processor built with ``clt=True``, which
    textures from the whole frame's CLT tiles (checked against the float64 reference above), bit for bit, with
    the ``valid`` mask. Bands of 1 and 2 rows wrap the ring (6 tile rows); the masked tiles of
    test_texture_in_bands_equals_reference (tiles on band edges with one contributing neighbour: the alpha
    fade reads the next band's ``finite``, stale from a measure at other targets until that band is converted)
    and an inactive one. Checked to fail: converting the next band after the combine, or a ring of ``rows``
    rows."""
    monkeypatch.setattr(buffers, "TEXTURE_BAND_ROWS", rows)
    rng = np.random.default_rng(52)
    _, frames = _scene(rng, 1.3)
    disparity = (1.3 + rng.uniform(-0.3, 0.3, size=(H // 8, W // 8))).astype(np.float32)
    for tile in [(2, 2), (2, 4), (1, 3), (3, 5), (3, 7), (4, 6), (4, 0), (4, 2)]:
        disparity[tile] = np.nan
    active = np.ones((H // 8, W // 8), bool)
    active[3, 1] = False
    banded = TileProcessor(H, W, textures=True, device=device, backend=backend)
    whole = TileProcessor(H, W, textures=True, clt=True, device=device, backend=backend)
    assert banded._buffers.clt is None and banded._buffers.tex_rgba.shape[0] == min(rows + 1, H // 8) * (W // 8) * 4
    for tp in (banded, whole):
        tp.load(frames)
        tp.measure(0.0)  # other targets first: the texture must convert at its own
        tp.set_targets(disparity, active=active)
        tp.texture()
    for name in ("texture", "valid"):
        torch.testing.assert_close(getattr(banded.result, name), getattr(whole.result, name), rtol=0, atol=0)
    got = banded.process(frames, disparity, active=active)
    torch.testing.assert_close(got.texture, whole.process(frames, disparity, active=active).texture, rtol=0, atol=0)


def test_taichi_exp_matches_float64_exp():
    """The Taichi combine's e^x (kernels/taichi_texture.exp_f32, an inline float32 polynomial instead of libm).
    Oracle: NumPy's float64 exp; relative tolerance 1.5e-7 + 4e-8 |n|, n = x / ln 2 (the polynomial ~1 ulp plus
    n ln 2 rounded to float32, ~3.5e-8 per unit of n; measured 1.2e-7 at n = 0, 5.6e-7 at x = -10, 4.1e-6 at
    -72) on [-87, 2]; 0 below ln of the smallest normal float (-87.33). Checked to fail: the last polynomial
    coefficient 0.5 -> 0.49, or n rounded towards zero (r then reaches -ln 2, outside the polynomial's range)."""
    import taichi as ti

    from tpnet_gpu.runtime import taichi_setup
    from tpnet_gpu.kernels import taichi_texture
    from tpnet_gpu.kernels.taichi_types import F32_1D

    taichi_setup.init_taichi("cpu")

    @ti.kernel
    def exp_of(x: F32_1D, out: F32_1D):
        for i in x:
            out[i] = taichi_texture.exp_f32(x[i])

    x = np.concatenate([np.linspace(-87.0, 2.0, 400_001), -np.logspace(-8, 1, 2001), [0.0, -87.4, -100.0, -1e30]])
    x = x.astype(np.float32)
    got = torch.zeros(len(x))
    exp_of(torch.from_numpy(x), got)
    got = got.numpy()
    inside = x >= -87.0
    want = np.exp(x[inside].astype(np.float64))
    tolerance = 1.5e-7 + 4e-8 * np.abs(x[inside]) / np.log(2.0)
    assert np.all(np.abs(got[inside] - want) / want <= tolerance)
    assert np.all(got[x < -87.33] == 0)
