"""Strips, their combination and the centre of mass (tpnet_gpu/baseline/strips.py). Oracles: the window
values printed in geometry_and_lma.md C.2, hand-placed cells, and synthetic peaks at known shifts."""

import numpy as np
import pytest

from tpnet_gpu.baseline import strips as st

LAGS = np.arange(-7, 8)


def synthetic(delta, width=1.5):
    """Gaussian pair peaks at -delta x pair axis (geometry_and_lma.md B.2), ``(T, 6, 15, 15)``."""
    delta = np.asarray(delta, dtype=np.float64)
    corr = np.zeros((len(delta), 6, 15, 15))
    for p, (ux, uy) in enumerate(st.PAIR_AXES):
        dx, dy = -delta * ux, -delta * uy
        corr[:, p] = np.exp(-((LAGS[None, None, :] - dx[:, None, None]) ** 2
                              + (LAGS[None, :, None] - dy[:, None, None]) ** 2) / (2 * width**2))
    return corr


def test_windows_match_the_spec():
    np.testing.assert_allclose(st.WINDOW_Y, [0.5, 0.25])
    np.testing.assert_allclose(st.WINDOW_X, [0.16667] * 4 + [0.16259, 0.13232, 0.08333, 0.03435, 0.00408], atol=5e-6)


def test_strip_row0_reads_the_pair_axis():
    corr = np.zeros((1, 6, 15, 15))
    corr[0, 0, 7, 7 + 3] = 1.0  # horizontal pair: lag (x=3, y=0)
    corr[0, 2, 7 - 2, 7] = 1.0  # vertical pair: lag (x=0, y=-2)
    corr[0, 4, 7 + 1, 7 + 1] = 1.0  # main diagonal: (1, 1)
    corr[0, 5, 7 + 2, 7 - 2] = 1.0  # other diagonal (1, -1) direction: s = -2 at (x=-2, y=2)
    strips = st.pair_strips(corr)
    assert strips[0, 0, 0, 7 + 3] == 1.0 and strips[0, 2, 0, 7 - 2] == 1.0
    assert strips[0, 4, 0, 7 + 1] == 1.0 and strips[0, 5, 0, 7 - 2] == 1.0
    assert strips[0, 0, 2, 7 + 3] == 0.0  # row 2 is one disparity unit off the axis


def test_combination_rules():
    s = np.zeros((1, 6, 9, 15))
    s[0, :, 0, 5] = [0.5, 0.3, 0.4, 0.2, 0.6, 0.1]
    geo = st.combine_strips(s, offset=0.1)[0, 0, 5]
    assert geo == pytest.approx(np.prod(np.array([0.6, 0.4, 0.5, 0.3, 0.7, 0.2])) ** (1 / 6) - 0.1)
    assert st.combine_strips(s, offset=-1)[0, 0, 5] == pytest.approx(s[0, :, 0, 5].mean())
    s[0, 3, 0, 5] = -0.5  # a factor <= 0 zeroes the geometric mean
    assert st.combine_strips(s, offset=0.1)[0, 0, 5] == 0.0


def test_centre_of_mass_finds_known_shifts():
    delta = np.array([0.0, 0.3, -1.37, 2.4, -3.2, 4.6])
    com = st.centre_of_mass(st.combine_strips(st.pair_strips(synthetic(delta))))
    np.testing.assert_array_equal(com.x_int, np.round(-delta))
    # The windowed CM is biased toward the integer maximum (spec: the LMA refines it); measured <= 0.1 px.
    assert np.max(np.abs(com.disparity - delta)) <= 0.15


def test_weak_or_empty_tiles_are_rejected():
    corr = np.concatenate([synthetic([1.0]) * 0.01, np.zeros((1, 6, 15, 15)), np.full((1, 6, 15, 15), np.nan)])
    com = st.centre_of_mass(st.combine_strips(st.pair_strips(corr)))
    assert np.isnan(com.x_cm).all() and np.all(com.strength == 0)


def test_bad_shape():
    with pytest.raises(ValueError, match=r"corr: expected shape \(tiles, 6, 15, 15\), got \(6, 15, 15\)"):
        st.pair_strips(np.zeros((6, 15, 15)))
