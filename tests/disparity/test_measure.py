"""Per-tile peak measurement (tpnet_gpu/disparity/measure.py): ``Peak2D`` and the LMA's quad slots. Oracle:
synthetic correlations with a Gaussian peak at a known 2-D lag, each lag's value scaled by the windows' overlap at
that lag (what windowing does to the correlation of a shifted tile: the envelope the measurement divides out);
pair directions worked out by hand from the cameras' offsets."""

import numpy as np
import pytest
import torch

from tpnet_gpu import tables
from tpnet_gpu.config import EngineConfig
from tpnet_gpu.disparity.measure import Measurer, Peak2D, gaussian_blur, lma_slots, parabola_step
from tpnet_gpu.disparity.pairs import AxisSampler, pair_vectors, window_overlap


def _peaks(points, sigma=1.2):
    lags = np.arange(-7, 8)
    envelope = window_overlap(lags)[:, None] * window_overlap(lags)[None, :]
    out = [np.exp(-((lags[None, :] - x) ** 2 + (lags[:, None] - y) ** 2) / (2 * sigma**2)) * envelope
           for x, y in points]
    return torch.tensor(np.array(out), dtype=torch.float32)


def test_gaussian_blur_is_scipys_seven_tap_filter_with_edges_replicated():
    # Oracle: scipy.ndimage.gaussian_filter, mode "nearest" (= edges replicated), truncated to 3 px (7 taps)
    from scipy.ndimage import gaussian_filter

    corr = np.random.default_rng(3).normal(size=(5, 2, 15, 15))
    got = gaussian_blur(torch.tensor(corr, dtype=torch.float32), 0.9).numpy()
    want = gaussian_filter(corr, sigma=(0, 0, 0.9, 0.9), mode="nearest", truncate=3 / 0.9)
    np.testing.assert_allclose(got, want, atol=2e-6)


@pytest.mark.parametrize("widen", [False, True])
def test_peak_2d_finds_known_lags(widen):
    """The flow's iteration re-centres on the measured peak, so what it needs is a contraction: every lag within
    0.3 x its length (+ 0.01 px) of the truth - the iteration then converges to the zero lag, where the peak is
    exact (lag 0 within 1e-3). Measured: 0.016 px at 0.3 px unblurred, 0.06 blurred; 0.2-0.3 px at 4-5 px."""
    points = np.array([(0.0, 0.0), (0.3, -0.2), (-2.6, 1.45), (4.2, 3.7), (-5.5, -0.5)])
    lag, strength = Peak2D(torch.device("cpu"), widen=widen).measure(_peaks(points))
    error = np.linalg.norm(lag.numpy() - points, axis=1)
    assert np.all(error <= 0.3 * np.linalg.norm(points, axis=1) + 0.01), error
    assert error[0] < 1e-3
    assert torch.all(strength > 0.3)


def test_peak_2d_keeps_to_its_reach():
    """A stronger peak beyond ``reach`` is not chosen over a weaker one inside it."""
    corr = _peaks([(6.5, 0.0)]) + 0.6 * _peaks([(1.0, 1.0)])
    lag, _ = Peak2D(torch.device("cpu"), reach=4.0).measure(corr)
    np.testing.assert_allclose(lag.numpy()[0], (1.0, 1.0), atol=0.1)


def test_parabola_step_is_the_vertex():
    x0 = 0.3  # samples of -(x - x0)^2 at -1, 0, 1
    values = [torch.tensor([-((x - x0) ** 2)]) for x in (-1.0, 0.0, 1.0)]
    step, ok = parabola_step(*values)
    assert ok.item() and step.item() == pytest.approx(x0, abs=1e-6)


def test_row_chunks_into_a_buffer_are_the_named_rows():
    """Oracle: plain indexing ``x[index]``; more rows than one chunk, so the buffer is reused between chunks."""
    from tpnet_gpu.disparity.measure import CHUNK, RowBuffer, row_chunks

    x = torch.arange(3 * CHUNK * 2, dtype=torch.float32).view(3 * CHUNK, 2)
    index = torch.arange(1, 3 * CHUNK, 2)  # every other row: copies
    buffer = RowBuffer()
    seen = []
    for part, rows in row_chunks(x, index, buffer):
        assert torch.equal(rows, x[part])
        seen.append(part)
    assert torch.equal(torch.cat(seen), index) and len(seen) == 2
    assert buffer.rows(x, 1).data_ptr() == buffer.rows(x, 5).data_ptr()  # one buffer


@pytest.mark.parametrize("offsets, pairs, slots", [
    (tables.QUAD_OFFSETS, tables.QUAD_PAIRS, (0, 1, 2, 3, 4, 5)),  # the quad's own order
    (((-0.5, 0.0), (0.5, 0.0)), ((0, 1),), (0,)),  # binocular: lag (1, 0), the quad's top pair
    (((0.0, -0.5), (0.0, 0.5)), ((0, 1),), (2,)),  # one above the other: (0, 1), the left column pair
    (((0.5, 0.0), (-0.5, 0.0)), ((0, 1),), None),  # (-1, 0): no quad pair points that way
    (((-1.0, 0.0), (1.0, 0.0)), ((0, 1),), None),  # (2, 0): twice the quad's baseline
    (((-0.5, 0.0), (0.5, 0.0), (1.5, 0.0)), ((0, 1), (1, 2)), (0, 1)),  # two (1, 0) pairs: both horizontal slots
    (((-0.5, 0.0), (0.5, 0.0), (1.5, 0.0), (2.5, 0.0)), ((0, 1), (1, 2), (2, 3)), None),  # a third: no slot left
])
def test_lma_slots_by_pair_direction(offsets, pairs, slots):
    """Oracle: the lag vectors r_b - r_a by hand against the quad's (1, 0) x 2, (0, 1) x 2, (1, 1), (1, -1)."""
    assert lma_slots(pair_vectors(offsets, pairs)) == slots


def test_lma_reads_a_rigs_pairs_in_their_quad_slots():
    """Oracle: the quad's pairs in reverse order, each pair's synthetic peak at the lag of one known disparity
    (lag = 1.3 px x its lag vector): the LMA measurement equals the one of the quad's own order, and it finds the
    shift (a peak at lag +d x the vector reads as residual -d; within 0.1 px on these Gaussian peaks: measured
    -1.241, the axis measurement -1.287)."""
    vectors = pair_vectors(tables.QUAD_OFFSETS, tables.QUAD_PAIRS)
    corr = torch.stack([_peaks([1.3 * v], sigma=1.0)[0] for v in vectors])[None].repeat(3, 1, 1, 1)  # (3, 6, 15, 15)
    config = EngineConfig(measure="lma")

    def measure(pairs, c):
        m = Measurer(pairs, AxisSampler(tables.QUAD_OFFSETS, pairs, "cpu"), config)
        assert m.lma
        return m.measure(c, torch.ones(3, dtype=torch.bool))

    quad = measure(tables.QUAD_PAIRS, corr)
    reverse = measure(tables.QUAD_PAIRS[::-1], corr.flip(1))
    torch.testing.assert_close(reverse, quad)
    assert torch.isfinite(quad[0]).all() and (quad[0] + 1.3).abs().max() <= 0.1, quad
