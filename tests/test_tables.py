"""Tables against the numbers printed in tile_processor.md §9 (oracle: the spec's constants) and scipy."""

import numpy as np
import pytest

from tpnet_gpu import tables

# tile_processor.md §9, HWINDOW and the LPF first rows (5 decimals printed).
SPEC_HWINDOW = [0.098017, 0.290285, 0.471397, 0.634393, 0.773010, 0.881921, 0.956940, 0.995185]
SPEC_LPF_ROW0 = {
    0.9: [1, 0.87041, 0.65944, 0.43487, 0.24970, 0.12518, 0.05616, 0.02729],
    0.6: [1, 0.91167, 0.75782, 0.57470, 0.39864, 0.25576, 0.15881, 0.11072],
    0.4: [1, 0.94101, 0.83404, 0.69822, 0.55623, 0.42968, 0.33581, 0.28608],
    0.5: [1, 0.92599, 0.79429, 0.63199, 0.46863, 0.32891, 0.22915, 0.17772],
}


def test_half_sine_matches_spec_and_princen_bradley():
    w = tables.half_sine(np.arange(16))
    np.testing.assert_allclose(w[:8], SPEC_HWINDOW, atol=1e-6)
    np.testing.assert_allclose(w, w[::-1], atol=1e-15)  # symmetric
    np.testing.assert_allclose(w[:8] ** 2 + w[8:] ** 2, 1.0, atol=1e-15)  # perfect-reconstruction condition


@pytest.mark.parametrize("sigma", sorted(SPEC_LPF_ROW0))
def test_lpf_matches_spec_table(sigma):
    table = tables.lpf(sigma)
    np.testing.assert_allclose(table[0], SPEC_LPF_ROW0[sigma], atol=6e-6)  # 5 printed decimals
    np.testing.assert_allclose(table, np.outer(table[0], table[0]), atol=1e-15)  # separable


def test_autocorrelation_bound_from_lpf():
    # §6.4: sum(L_corr)/16 = 0.7323 for sigma 0.9.
    assert tables.lpf(0.9).sum() / 16 == pytest.approx(0.7323, abs=5e-5)


def test_fold_is_a_signed_permutation():
    for sine in (False, True):
        p = tables.fold_matrix(sine)
        assert np.all(np.abs(p).sum(axis=1) == 2)  # each folded cell receives two samples
        assert np.all(np.abs(p).sum(axis=0) == 1)


def test_cfa_positions():
    colour = tables.cfa_colour_index("GRBG", 2, 2)
    np.testing.assert_array_equal(colour, [[2, 0], [1, 2]])  # G R / B G, colour order R=0, B=1, G=2
    np.testing.assert_array_equal(tables.cfa_colour_index("RGGB", 2, 2), [[0, 2], [2, 1]])
    with pytest.raises(ValueError, match="cfa: expected one of .* got 'RGB'"):
        tables.cfa_red_position("RGB")
