"""8-point transforms against scipy.fft (oracle), tile_processor.md §2. Tolerance 1e-13 (float64 round-off)."""

import numpy as np
import pytest
import scipy.fft as sfft

from tpnet_gpu import reference as ref

RNG = np.random.default_rng(2)


@pytest.mark.parametrize(
    "ours, oracle",
    [
        (ref.dct4, lambda x, axis: sfft.dct(x, type=4, norm="ortho", axis=axis)),
        (ref.dst4, lambda x, axis: sfft.dst(x, type=4, norm="ortho", axis=axis)),
        (ref.dct2e, lambda x, axis: 0.25 * sfft.dct(x, type=2, axis=axis)),  # spec scale: 1/4 of scipy's
        (ref.dst2e, lambda x, axis: 0.25 * sfft.dst(x, type=2, axis=axis)),
    ],
    ids=["dct4", "dst4", "dct2e", "dst2e"],
)
@pytest.mark.parametrize("axis", [-1, 0])
def test_transform_equals_scipy(ours, oracle, axis):
    x = RNG.normal(size=(8, 8, 3)) if axis == 0 else RNG.normal(size=(5, 8))
    np.testing.assert_allclose(ours(x, axis=axis), oracle(x, axis), atol=1e-13)


@pytest.mark.parametrize("transform", [ref.dct4, ref.dst4])
def test_type4_is_self_inverse(transform):
    x = RNG.normal(size=(4, 8))
    np.testing.assert_allclose(transform(transform(x)), x, atol=1e-13)


def test_wrong_length_is_rejected():
    with pytest.raises(ValueError, match="x: expected 8 samples along axis -1, got 7"):
        ref.dct4(np.zeros(7))
