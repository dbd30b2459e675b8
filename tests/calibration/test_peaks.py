"""2-D pair peaks (tpnet_gpu/calibration/peaks.py). Oracle: correlations drawn as a paraboloid (exact for the
parabola fit: error < 1e-9 px) and as a Gaussian (the parabola's known pull toward whole lags: < 0.1 px) at known
sub-lag positions. Break tried: x and y swapped in the output (fails)."""

import numpy as np
import torch

from tpnet_gpu.calibration.peaks import REACH, pair_peaks


def _grid():
    lag = np.arange(-7, 8, dtype=np.float64)
    return np.meshgrid(lag, lag, indexing="ij")  # (my, mx)


def test_paraboloid_peak_exact():
    my, mx = _grid()
    truth = np.array([[2.3, -1.4], [-4.45, 0.2], [0.0, 0.0]])  # (x, y)
    corr = np.stack([1.0 - 0.05 * ((mx - x) ** 2 + 0.5 * (my - y) ** 2) for x, y in truth])[None]
    lags, strength = pair_peaks(torch.as_tensor(corr))
    assert np.max(np.abs(lags[0].numpy() - truth)) < 1e-9
    assert strength.shape == (1, 3)


def test_gaussian_peak_and_rim():
    my, mx = _grid()
    corr = np.exp(-((mx - 1.3) ** 2 + (my + 0.7) ** 2) / (2 * 1.2**2))
    flat = np.zeros_like(corr)
    lags, _ = pair_peaks(torch.as_tensor(np.stack([corr, flat])[None]))
    assert np.max(np.abs(lags[0, 0].numpy() - [1.3, -0.7])) < 0.1
    assert np.isnan(lags[0, 1].numpy()).all()  # no curvature: no peak
    assert REACH < 7  # the parabola reads one lag beyond the search
