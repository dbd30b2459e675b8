"""Network layers of any rig (net/layers.py). Oracles: the tile processor's own quad kernel
(``TileResult.layers``, bit for bit), the float64 reference ``reference.correlation.group_layers`` (binocular,
8-camera), and the physical fact that a swapped pair correlates to the point-mirror of the pair."""

import numpy as np
import pytest
import torch

from tpnet_gpu import tables
from tpnet_gpu.io import rigfile
from tpnet_gpu.camera import Rig
from tpnet_gpu.disparity.pairs import default_pairs, direction_groups
from tpnet_gpu.net.layers import QUAD_LAGS, NetworkLayers, lags_match, rig_lags
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.reference.correlation import group_layers, network_layers
from tpnet_gpu.scenes import Sensor, random_scene, render

H, W = 48, 64


@pytest.fixture(scope="module")
def quad_frame():
    """A rendered quad frame ``(4, H, W)`` and its ground-truth tile disparities (the targets)."""
    rig = Rig(width=W, height=H)
    rendered = render(random_scene(rig, np.random.default_rng(3)), rig, sensor=Sensor(), supersample=1, seed=1)
    return rendered.raws.astype(np.float32) - rendered.sensor.black_level, rendered.tile_disparity.astype(np.float32)


def test_quad_layers_are_the_kernels_bit_for_bit(quad_frame):
    frames, target = quad_frame
    result = TileProcessor(H, W).process(frames, target)
    layers = NetworkLayers(tables.QUAD_OFFSETS, tables.QUAD_PAIRS, "cpu")
    mine = layers(result.corr)
    assert mine.shape == result.layers.shape == (48, 4, 9, 9) and mine.dtype == torch.float32
    assert float(result.layers.abs().max()) > 0.1 and bool((result.layers == 0).any())  # peaks and zeroed cells
    assert torch.equal(mine, result.layers)  # the root in float64 rounded once = the kernel's IEEE sqrt
    assert layers.lags == QUAD_LAGS and layers.of(result) is result.layers


def test_swapped_pairs_mirror_onto_the_same_layers(quad_frame):
    """Pairs given as (b, a) correlate to the point-mirror of (a, b); their groups fold them back (mirrored), so
    the layers equal the kernel's of the spec's pairs (to float32 rounding of the correlation itself)."""
    frames, target = quad_frame
    swapped = tuple((b, a) for a, b in tables.QUAD_PAIRS)
    result = TileProcessor(H, W, pairs=swapped).process(frames, target)
    layers = NetworkLayers(tables.QUAD_OFFSETS, swapped, "cpu")
    assert all(m for g in layers.groups for _, m in g.members)
    expected = TileProcessor(H, W).process(frames, target).layers
    torch.testing.assert_close(layers(result.corr), expected, rtol=0, atol=2e-6)


@pytest.mark.parametrize("name", ["quad", "binocular", "two_quads"])
def test_layers_match_the_float64_reference(name):
    rig = rigfile.load(name)
    pairs = default_pairs(rig.offsets)
    rng = np.random.default_rng(7)
    corr = rng.normal(0.05, 0.2, (5, len(pairs), 15, 15)).astype(np.float32)  # both signs: zeroed cells too
    layers = NetworkLayers(rig.offsets, pairs, "cpu")
    want = group_layers(corr, direction_groups(rig.offsets, pairs))
    got = layers(torch.from_numpy(corr))
    assert got.shape == (5, {"quad": 4, "binocular": 1, "two_quads": 10}[name], 9, 9)
    np.testing.assert_allclose(got.numpy(), want, rtol=0, atol=1e-6)  # float32 sums and products
    if name == "quad":  # the reference's quad layers are the same groups
        np.testing.assert_array_equal(want, network_layers(corr))
    if name == "binocular":  # one pair: its centre crop as it is
        np.testing.assert_array_equal(got.numpy()[:, 0], corr[:, 0, 3:12, 3:12])


def test_plain_mean_for_a_negative_offset():
    rig = rigfile.load("two_quads")
    pairs = default_pairs(rig.offsets)
    corr = np.random.default_rng(2).normal(0.0, 0.3, (3, len(pairs), 15, 15)).astype(np.float32)
    got = NetworkLayers(rig.offsets, pairs, "cpu", offset=-1.0)(torch.from_numpy(corr))
    want = group_layers(corr, direction_groups(rig.offsets, pairs), offset=-1.0)
    np.testing.assert_allclose(got.numpy(), want, rtol=0, atol=1e-6)


def test_rig_lags_and_matching():
    assert rig_lags(tables.QUAD_OFFSETS) == ((1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, -1.0))
    assert rig_lags(rigfile.load("binocular").offsets) == ((1.0, 0.0),)
    left = rigfile.load("binocular").referenced_to(0)  # the reference camera moves no lag
    assert lags_match(rig_lags(left.offsets), ((1.0, 0.0),))
    assert not lags_match(((2.0, 0.0),), ((1.0, 0.0),)) and not lags_match(QUAD_LAGS, ((1.0, 0.0),))
    assert lags_match([[1.0, 0.0]], ((1.0 + 1e-9, 0.0),))


def test_rejects_bad_correlations():
    layers = NetworkLayers(tables.QUAD_OFFSETS, tables.QUAD_PAIRS, "cpu")
    with pytest.raises(ValueError, match=r"corr: expected shape \(tiles, 6, 15, 15\), got \(3, 5, 15, 15\)"):
        layers(torch.zeros(3, 5, 15, 15))
    with pytest.raises(TypeError, match="corr: expected a floating-point torch.Tensor, got ndarray"):
        layers(np.zeros((3, 6, 15, 15)))
