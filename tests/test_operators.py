"""Host-built operators (tpnet_gpu/operators.py) against independent oracles: scipy's transforms and explicit
sums over the spec's formulas (tile_processor.md §6.3, §7.1). Tolerance 1e-12 (float64)."""

import numpy as np
import scipy.fft

from tpnet_gpu import operators, tables


def test_lag_operator_is_the_spec_sum():
    """R(m) = 1/4 sum_k X[k] cos(omega_k m) (cosine) or sin(omega_k m) (sine), for lags -7..7 (§6.3)."""
    m = np.arange(-7, 8)[:, None]
    for sine, phi in ((False, np.cos), (True, np.sin)):
        expected = 0.25 * phi(m * tables.omega()[None, :])
        np.testing.assert_allclose(operators.lag_operator(sine), expected, atol=1e-12)


def test_lag_matrix_equals_per_quadrant_products():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 8, 8))
    a = operators.lag_operators()
    direct = sum(a[q >> 1] @ x[q] @ a[q & 1].T for q in range(4))
    np.testing.assert_allclose((x.reshape(-1) @ operators.lag_matrix()).reshape(15, 15), direct, atol=1e-12)


def test_unfold_gather_reproduces_the_unfold_matrix():
    index, sign = operators.unfold_gather()
    for sine in (0, 1):
        u = np.zeros((15, 8))
        u[np.arange(15), index[sine]] = sign[sine]
        np.testing.assert_array_equal(u, tables.unfold_matrix(bool(sine), 7))


def test_half_dtt2e_is_a_quarter_of_scipy_dct2():
    x = np.random.default_rng(1).normal(size=8)
    np.testing.assert_allclose(operators.half_dtt2e()[0] @ x, 0.125 * scipy.fft.dct(x, 2), atol=1e-12)
    np.testing.assert_allclose(operators.half_dtt2e()[1] @ x, 0.125 * scipy.fft.dst(x, 2), atol=1e-12)


def test_inverse_axes_undo_the_forward_fold_at_zero_shift():
    """1-D forward MCLT (window, signed fold, DCT-IV) of both branches, then ``inverse_axis`` of each, summed:
    w(n)^2 per sample (time-domain aliasing cancels between the cosine and the sine branch)."""
    w = tables.half_sine(np.arange(16))
    both = sum(operators.inverse_axis(sine) @ (tables.dtt4_matrix(sine) @ tables.fold_matrix(sine) * w)
               for sine in (False, True))
    np.testing.assert_allclose(both, np.diag(w**2), atol=1e-12)


def test_colour_masks_pick_each_pixel_once_per_parity():
    for cfa in tables.CFA_RED_POSITION:
        masks = operators.colour_masks(cfa)
        assert masks.shape == (4, 3, 16, 16)
        unscaled = masks / np.array([1.0, 1.0, tables.GREEN_PRESCALE])[None, :, None, None]
        np.testing.assert_array_equal(unscaled.sum(axis=1), 1.0)
        colour = tables.cfa_colour_index(cfa, 18, 18)
        for parity in range(4):
            py, px = parity >> 1, parity & 1
            np.testing.assert_array_equal(unscaled[parity].argmax(axis=0), colour[py : py + 16, px : px + 16])
    assert operators.colour_masks(None).shape == (4, 1, 16, 16)


def test_window_squared_is_outer_of_squared_half_sine():
    w2 = np.sin(np.pi * (2 * np.arange(16) + 1) / 32) ** 2
    np.testing.assert_allclose(operators.window_squared(), np.outer(w2, w2), atol=1e-15)
