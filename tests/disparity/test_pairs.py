"""Pair geometry and axis sampling (tpnet_gpu/disparity/pairs.py). Oracles: the quad's pair directions of the
spec (geometry_and_lma.md B.1), explicit window sums, and synthetic correlations with a peak at a known lag."""

import numpy as np
import pytest
import torch

from tpnet_gpu import tables
from tpnet_gpu.io import rigfile
from tpnet_gpu.disparity.pairs import (AxisSampler, combine_pairs, default_pairs, direction_groups, pair_vectors,
                                       window_overlap)


def test_quad_pair_vectors_are_the_spec_directions():
    expected = ((1, 0), (1, 0), (0, 1), (0, 1), (1, 1), (1, -1))  # hor-top ... diag-other (B.1)
    np.testing.assert_array_equal(pair_vectors(tables.QUAD_OFFSETS, tables.QUAD_PAIRS), expected)


def test_window_overlap_is_the_window_autocorrelation():
    w = np.sin(np.pi * (2 * np.arange(16) + 1) / 32)
    for k in (0, 1, 5, 11):
        assert window_overlap(k) == pytest.approx(np.dot(w[: 16 - k], w[k:]) / np.dot(w, w), abs=1e-12)
    assert window_overlap(16) == 0.0 and window_overlap(-3) == window_overlap(3)


def gaussian_peaks(vectors: np.ndarray, e: float, sigma: float = 1.2) -> torch.Tensor:
    """``(1, P, 15, 15)`` correlations with a Gaussian peak at lag -e v per pair, scaled by the window overlap
    there (what a true shift of e does to a windowed tile)."""
    lags = np.arange(-7, 8)
    out = []
    for vx, vy in vectors:
        x0, y0 = -e * vx, -e * vy
        g = np.exp(-((lags[None, :] - x0) ** 2 + (lags[:, None] - y0) ** 2) / (2 * sigma**2))
        out.append(g * window_overlap(x0) * window_overlap(y0))
    return torch.tensor(np.array(out)[None], dtype=torch.float32)


@pytest.mark.parametrize("offsets, pairs", [
    (tables.QUAD_OFFSETS, tables.QUAD_PAIRS),
    (((-0.5, 0.0), (0.5, 0.0)), ((0, 1),)),
    (((-1.5, 0.0), (-0.5, 0.0), (0.5, 0.0), (1.5, 0.0)), ((0, 1), (0, 3), (1, 2))),
])
def test_sampled_axis_peaks_at_the_true_offset_with_full_height(offsets, pairs):
    sampler = AxisSampler(offsets, pairs, "cpu")
    vectors = pair_vectors(offsets, pairs)
    e_true = 1.75
    corr = gaussian_peaks(vectors, e_true)
    e = torch.arange(-2.0, 2.01, 0.25)
    values = sampler.sample(corr, e, "bicubic")
    combined = combine_pairs(values)[0]
    assert float(e[torch.argmax(combined)]) == pytest.approx(e_true)
    assert float(combined.max()) == pytest.approx(1.0, abs=0.03)  # the overlap loss undone


def test_lags_beyond_the_correlation_are_nan_and_left_out():
    sampler = AxisSampler(((-1.5, 0.0), (1.5, 0.0), (-0.5, 0.0)), ((0, 1), (2, 1)), "cpu")  # |v| = 3 and 2
    values = sampler.sample(torch.ones(1, 2, 15, 15), torch.tensor([3.0]))  # lags -9 and -6
    assert torch.isnan(values[0, 0, 0]) and torch.isfinite(values[0, 1, 0])
    assert torch.isfinite(combine_pairs(values)).all()
    assert torch.isnan(combine_pairs(torch.full((1, 2, 1), float("nan")))).all()


def test_sampling_across_the_axis_from_an_origin():
    """``vectors`` / ``origin`` / ``normalise``: a Gaussian at lag (2, -1) read along (0, 1) from that lag at whole
    offsets gives its own values (bicubic interpolation is exact on the lag grid): exp(-1 / (2 s^2)), 1, ... raw;
    divided by the window overlap at each lag when normalised."""
    sigma, x0, y0 = 1.2, 2.0, -1.0
    lags = np.arange(-7, 8)
    g = np.exp(-((lags[None, :] - x0) ** 2 + (lags[:, None] - y0) ** 2) / (2 * sigma**2))
    corr = torch.tensor(np.broadcast_to(g, (1, 1, 15, 15)).copy(), dtype=torch.float32)
    sampler = AxisSampler(((-0.5, 0.0), (0.5, 0.0)), ((0, 1),), "cpu")
    e = torch.tensor([-1.0, 0.0, 1.0])
    kwargs = {"vectors": torch.tensor([[0.0, 1.0]]), "origin": torch.tensor([[[x0, y0]]])}
    raw = sampler.sample(corr, e, "bicubic", normalise=False, **kwargs)[0, 0].numpy()
    expected = np.exp(-np.array([1.0, 0.0, 1.0]) / (2 * sigma**2))  # lags (2, 0), (2, -1), (2, -2)
    np.testing.assert_allclose(raw, expected, atol=1e-5)
    normalised = sampler.sample(corr, e, "bicubic", **kwargs)[0, 0].numpy()
    overlap = window_overlap(2.0) * window_overlap(np.array([0.0, 1.0, 2.0]))
    np.testing.assert_allclose(normalised, expected / overlap, rtol=1e-4)


# --------------------------------------------------------------------------------------- direction groups
def test_quad_groups_are_the_network_layers():
    """Oracle: network.md §1 - hor = pairs 0, 1; vert = 2, 3; diag-main = 4; diag-other = 5, in that order."""
    groups = direction_groups(tables.QUAD_OFFSETS, tables.QUAD_PAIRS)
    assert [g.lag for g in groups] == [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
    assert [g.members for g in groups] == [((0, False), (1, False)), ((2, False), (3, False)), ((4, False),),
                                           ((5, False),)]


def test_opposite_pairs_fold_mirrored():
    swapped = [(1, 0), (2, 3), (2, 0), (1, 3), (3, 0), (1, 2)]  # every pair but two reversed
    groups = direction_groups(tables.QUAD_OFFSETS, swapped)
    assert [g.lag for g in groups] == [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
    assert [g.members for g in groups] == [((0, True), (1, False)), ((2, True), (3, False)), ((4, True),),
                                           ((5, True),)]


def test_binocular_has_one_group():
    assert direction_groups(((-0.5, 0.0), (0.5, 0.0)), [(0, 1)]) == (((1.0, 0.0), ((0, False),)),)
    assert direction_groups(((0.0, 0.0), (0.0, 1.0)), [(1, 0)]) == (((0.0, 1.0), ((0, True),)),)  # vertical


def test_eight_camera_groups_by_lag_vector():
    """two_quads (4x2 grid, rig_file.md §4): every pair in exactly one group, whose lag is the pair's lag or its
    negative (as flagged); lags differ in direction or length; order by length, then angle mod 180."""
    offsets = rigfile.load("two_quads").offsets
    pairs = default_pairs(offsets)
    groups = direction_groups(offsets, pairs)
    expected = [(1, 0), (0, 1), (1, 1), (1, -1), (2, 0), (2, 1), (2, -1), (3, 0), (3, 1), (3, -1)]
    assert [g.lag for g in groups] == [tuple(map(float, v)) for v in expected]
    seen = sorted(p for g in groups for p, _ in g.members)
    assert seen == list(range(len(pairs))) == list(range(28))
    r = np.asarray(offsets)
    for g in groups:
        for p, mirrored in g.members:
            a, b = pairs[p]
            np.testing.assert_allclose((r[b] - r[a]) * (-1 if mirrored else 1), g.lag, atol=1e-12)
    assert [len(g.members) for g in groups] == [6, 4, 3, 3, 4, 2, 2, 2, 1, 1]


def test_direction_groups_reject_bad_pairs():
    with pytest.raises(ValueError, match=r"pairs: expected a non-empty list of \(a, b\) camera indices in 0..1"):
        direction_groups(((-0.5, 0.0), (0.5, 0.0)), [(0, 2)])
    with pytest.raises(ValueError, match="pairs: a pair of cameras at the same offset has no lag direction"):
        direction_groups(((0.0, 0.0), (0.0, 0.0)), [(0, 1)])


@pytest.mark.parametrize("offsets, pairs", [
    (tables.QUAD_OFFSETS, tables.QUAD_PAIRS),
    (((-1.5, 0.0), (1.5, 0.0), (-0.5, 0.0)), ((0, 1), (2, 1))),  # |v| = 3 and 2: lags fall outside
])
def test_table_reads_are_the_per_tile_reads(offsets, pairs):
    """Oracle: a Gaussian peak at a known offset (1.75 px) found at its offset by the table reads, and the table
    reads (``uniform``: one grid for every tile; ``table`` + ``sample_rows``: a row of offsets per tile) bitwise
    equal to ``sample`` with each tile's offsets made per call (the path the peak tests above check)."""
    sampler = AxisSampler(offsets, pairs, "cpu")
    peak = gaussian_peaks(pair_vectors(offsets, pairs), 1.75)
    corr = torch.cat([peak, torch.rand(4, len(pairs), 15, 15, generator=torch.Generator().manual_seed(0))])
    e = torch.arange(-3.0, 3.01, 0.25)
    got = sampler.sample_uniform(corr, sampler.uniform(e, 8), "bicubic")
    want = sampler.sample(corr, e, "bicubic")
    assert torch.equal(got.isnan(), want.isnan()) and torch.equal(got.nan_to_num(), want.nan_to_num())
    bilinear = sampler.sample_uniform(corr, sampler.uniform(e, 8))
    assert torch.equal(bilinear.nan_to_num(), sampler.sample(corr, e).nan_to_num())
    assert float(e[torch.argmax(combine_pairs(got)[0])]) == pytest.approx(1.75)
    rows = e[:, None] + torch.arange(-1.0, 1.01, 0.25)[None, :]  # (K, 9) like the measurer's fine windows
    pick = torch.tensor([19, 3, 0, 14, 19])  # row 19: 1.75 + (-1 .. 1) for the peak's tile
    got = sampler.sample_rows(corr, sampler.table(rows), pick, "bicubic")
    want = sampler.sample(corr, rows[pick], "bicubic")
    assert torch.equal(got.isnan(), want.isnan()) and torch.equal(got.nan_to_num(), want.nan_to_num())
    assert float(rows[19][torch.argmax(combine_pairs(got)[0])]) == pytest.approx(1.75)
