"""2-D pair peaks (tpnet_gpu/calibration/peaks.py). Oracle: correlations drawn as an anisotropic Gaussian (exact
for the log-parabola fit: error < 1e-9 px) and as a paraboloid with non-positive neighbours (the plain parabola,
exact there) at known sub-lag positions. Break tried: x and y swapped in the output (fails); the plain parabola
for the Gaussian (0.03 px off: fails)."""

import numpy as np
import torch

from tpnet_gpu.calibration.peaks import REACH, pair_peaks


def _grid():
    lag = np.arange(-7, 8, dtype=np.float64)
    return np.meshgrid(lag, lag, indexing="ij")  # (my, mx)


def test_gaussian_peak_exact():
    my, mx = _grid()
    truth = np.array([[2.3, -1.4], [-4.45, 0.2], [0.0, 0.0]])  # (x, y)
    corr = np.stack([np.exp(-0.3 * (mx - x) ** 2 - 0.15 * (my - y) ** 2) for x, y in truth])[None]
    lags, strength = pair_peaks(torch.as_tensor(corr))
    assert np.max(np.abs(lags[0].numpy() - truth)) < 1e-9
    assert strength.shape == (1, 3)


def test_plain_parabola_where_neighbours_not_positive():
    my, mx = _grid()
    corr = 0.1 - 0.5 * ((mx - 1.3) ** 2 + (my + 0.4) ** 2)  # the peak's neighbours are negative
    flat = np.zeros_like(corr)
    lags, _ = pair_peaks(torch.as_tensor(np.stack([corr, flat])[None]))
    assert np.max(np.abs(lags[0, 0].numpy() - [1.3, -0.4])) < 1e-9
    assert np.isnan(lags[0, 1].numpy()).all()  # no curvature: no peak
    assert REACH < 7  # the parabola reads one lag beyond the search
